"""fuzzyslam.streams"""
