"""sonicspec.acoustics"""
