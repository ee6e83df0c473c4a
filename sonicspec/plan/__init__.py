"""sonicspec.plan"""
