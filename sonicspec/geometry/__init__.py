"""sonicspec.geometry"""
