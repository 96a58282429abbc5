"""marker-pose-graph: the pose of a target carrying markers, from 3D marker coordinates measured
by a motion-capture rig (level A), refined by an SE(3) pose graph (GTSAM).

The package imports nothing from jobs/, api/, cli/ or the client; GTSAM and scipy are imported
inside the functions that need them.
"""
