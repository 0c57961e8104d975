"""fuzzyslam.evaluation"""
