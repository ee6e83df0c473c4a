"""sonicspec.audio"""
