"""Lidar-IMU extrinsic calibration from static poses (paper Section IV.A, Fig. 10-11).

Runs on a real rig as well as on the simulator's: it takes accumulated point clouds (one per static
pose, lidar frame), IMU samples and the static windows, and returns the extrinsic.

* :mod:`.se3` — rigid transforms, Exp/Log on SO(3) and SE(3), the error metric of eq. (8);
* :mod:`.registration` — the lidar's relative motion between two poses (point-to-plane ICP);
* :mod:`.imu_integration` — the IMU's relative motion (biases from the static poses);
* :mod:`.handeye` — the extrinsic from AX = XB (Park & Martin 1994, refined by a joint weighted fit),
  with degeneracy checks;
* :mod:`.pair_check` — pose pairs checked against each other, outliers removed and named;
* :mod:`.uncertainty` — a 1-sigma never smaller than the pairs allow (none with too few);
* :mod:`.procedure` — the whole procedure on one set of poses.
"""
