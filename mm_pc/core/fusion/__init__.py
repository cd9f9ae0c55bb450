"""Fusion: the pose EKF, its input records and the one fusion loop."""
