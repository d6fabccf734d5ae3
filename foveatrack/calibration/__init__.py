"""Speed-table calibration by tracking a room corner (paper Appendix D.4).

"We calibrate the gimbal's rotation speed by tracking a pre-known feature point (e.g. a room corner)
in the lidar point cloud.  The calibration builds a lookup table mapping the command to actual
rotation speed."

* :mod:`~foveatrack.calibration.plan` -- the plan, the feature, the legs and the report
* :mod:`~foveatrack.calibration.corner` -- the corner in a frame (RANSAC planes) and rotation geometry
* :mod:`~foveatrack.calibration.procedure` -- :class:`Calibrator` (the state machine and the
  per-leg estimator) and :class:`PriorAxisCalibrator` (the joint estimator the product runs)
* :mod:`~foveatrack.calibration.drive` -- running a calibrator from any frame source into any sink
* :mod:`~foveatrack.calibration.live` -- that, on the live devices of a daemon config
"""

from foveatrack.calibration.corner import find_corner
from foveatrack.calibration.plan import DEFAULT_BYTES, CalibrationPlan, CalibrationReport, FeatureSpec, LegRecord
from foveatrack.calibration.procedure import Calibrator, PriorAxisCalibrator

__all__ = ["DEFAULT_BYTES", "CalibrationPlan", "CalibrationReport", "Calibrator", "FeatureSpec", "LegRecord",
           "PriorAxisCalibrator", "find_corner"]
