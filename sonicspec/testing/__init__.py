"""sonicspec.testing"""
