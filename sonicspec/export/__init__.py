"""sonicspec.export"""
