"""The ``bearings`` kind: many targets located from two bearings-only (infrared) stations.

Per frame, detections at the two stations are associated by their angle about the baseline
(the epipolar angle), gated by a chi-square test, assigned one-to-one, and each pair is
triangulated by maximum likelihood with its covariance; fixes are then linked into tracks.
The paper's method (elevation difference, direction histogram, Mean Shift) is kept as
``method="paper"`` for comparison.
"""
