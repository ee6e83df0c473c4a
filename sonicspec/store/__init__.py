"""sonicspec.store"""
