"""Scene sources: readers that turn a dataset layout into :class:`aias_augment.core.frame.Frame` records.

- :mod:`.kitti`: KITTI odometry layout (calib P0..P3 or a pyslam yaml, poses, left/right images), stereo depth.
- :mod:`.dgp`: DGP/DDAD scenes (cameras, LiDAR, extrinsics, 3D boxes).
- :mod:`.nyu`: RGB-D frames with poses (NYU / TUM-style pose lines).
- :mod:`.stereo`: depth from a rectified stereo pair (a stereo scene's depth input).
- :mod:`.video`: camera motion from tracked features with a given K.
"""
