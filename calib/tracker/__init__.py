"""Online tracking of a gyro's bias with a Kalman filter, seeded from an offline calibration.

The state is the bias ``b`` (Calibration v1 convention: added to the reading), optionally with
a linear temperature coefficient; it walks randomly (``K``, the rate random walk) and is
measured while the sensor is still (``m = −b + v``) or while a servo of the jig turns it at
an encoder-known rate. Read the pieces in this order, each a module of its own:

1. :mod:`.settings`: the noise model and tuning (:class:`TrackerSettings`).
2. :mod:`gyrocal.calib.stationarity`: when the sensor is still, from its readings' variance
   and a rate test centred on the seed, never on the estimate it feeds (a detector gated on
   the tracker's own bias never sees a sensor whose bias moved since calibration), and the
   accelerometer's veto where ``accel_noise_std`` is given (a steady slow turn tilts gravity).
3. :mod:`.pooling`: decided samples pooled into update windows (the measurements).
4. :mod:`.step`: one Kalman step per window (the model's equations), the seed check that
   reports a bias that moved since calibration, and the NIS and CUSUM health tests.
5. :mod:`.qbank`: the random walk ``K`` estimated from the data by a bank of filters.
6. :mod:`.smoother`: replay, the Rauch-Tung-Striebel smoother over the kept states.
7. :mod:`.streaming`: a sample at a time (:meth:`BiasTracker.update`) and in blocks
   (:meth:`BiasTracker.feed`), with the same estimates as a batch.
8. :mod:`.core`: :class:`BiasTracker`, which joins them (state, validation,
   :meth:`BiasTracker.process`, per-sample output).
9. :mod:`.results`: what comes back (:class:`TrackResult`, :class:`UpdateLog`,
   :class:`Health`, :class:`BiasMoved`).
"""

from gyrocal.calib.tracker.core import BiasTracker
from gyrocal.calib.tracker.results import BiasMoved, Health, TrackResult, UpdateLog
from gyrocal.calib.tracker.settings import ENCODER_TICK_RAD, TrackerSettings

__all__ = [
    "ENCODER_TICK_RAD",
    "BiasMoved",
    "BiasTracker",
    "Health",
    "TrackResult",
    "TrackerSettings",
    "UpdateLog",
]
