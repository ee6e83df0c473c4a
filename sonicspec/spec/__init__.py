"""sonicspec.spec"""
