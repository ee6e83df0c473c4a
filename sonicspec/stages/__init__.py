"""sonicspec.stages"""
