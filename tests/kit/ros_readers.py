"""Models of the reading code of the ROS-world consumers of gyrocal's exports, written from
their sources (which are not in this repository and not installed here), file and line cited.

Kalibr, ethz-asl/kalibr commit 1f60227,
``aslam_offline_calibration/kalibr/python/kalibr_common/ConfigReader.py``:

- ``ParametersBase.readYaml`` (lines 206-214): ``yaml.safe_load`` of the file;
  ``raiseError`` (lines 233-235): ``RuntimeError("[ImuConfig Reader]: " + message)``
  (``ImuParameters.__init__`` names the reader "ImuConfig", line 430);
- ``catch_keyerror`` (lines 183-190): a missing key becomes
  ``"Field {e} missing in file: {yamlFile}"`` with ``e`` the KeyError, whose text is the quoted
  key: "Field 'accelerometer_random_walk' missing";
- ``getRosTopic`` (lines 436-443): a ``str``; ``getUpdateRate`` (lines 450-457): ``> 0``;
  ``getAccelerometerStatistics`` (lines 464-474) and ``getGyroStatistics`` (lines 482-492): both
  figures ``> 0``, and the discrete noise ``noise_density / sqrt(1 / update_rate)``;
- ``printDetails`` (lines 503-517) calls all of them; ``kalibr_calibrate_imu_camera`` does
  ``ImuParameters(imu_yaml)`` then ``printDetails()`` first thing (lines 150-151).

imu_calib, dpkoch/imu_calib commit 59f5d17, ``src/accel_calib/accel_calib.cpp``:

- ``AccelCalib::loadCalib`` (lines 69-95): ``YAML::LoadFile``; ``SM`` a sequence of 9 and
  ``bias`` of 3 (the asserts, lines 75-76); ``SM_(i/3, i%3) = node["SM"][i]`` (line 80, row
  major), ``bias_(i) = node["bias"][i]`` (line 85); any exception: not loaded (lines 91-94);
- ``AccelCalib::applyCalib`` (lines 212-221): ``corrected = SM_ * raw - bias_``, which
  ``ApplyCalib::rawImuCallback`` applies to ``linear_acceleration`` (``src/apply_calib.cpp``,
  lines 98-99).

yaml-cpp and PyYAML's safe loader read the flow sequences of plain floats gyrocal writes alike.
"""

from __future__ import annotations

import functools
import json
import math
from pathlib import Path

import numpy as np
import yaml

#: The fields ConfigReader.py's ImuParameters reads, as listed above (not gyrocal's table).
KALIBR_REQUIRED = ("rostopic", "update_rate", "accelerometer_noise_density",
                   "accelerometer_random_walk", "gyroscope_noise_density",
                   "gyroscope_random_walk")


class KalibrImuConfig:
    """``kalibr_common.ImuParameters`` reading a file, as modelled above."""

    def __init__(self, text: str, yaml_file: str = "imu.yaml") -> None:
        self.yamlFile = yaml_file
        self.data = yaml.safe_load(text)

    def raiseError(self, message: str) -> None:
        raise RuntimeError(f"[ImuConfig Reader]: {message}")

    def _field(self, key: str):
        try:
            return self.data[key]
        except KeyError as e:
            self.raiseError(f"Field {e} missing in file: {self.yamlFile}")

    def getRosTopic(self) -> str:
        topic = self._field("rostopic")
        if not isinstance(topic, str):
            self.raiseError("rostopic has to be a string")
        return topic

    def getUpdateRate(self) -> float:
        rate = self._field("update_rate")
        if rate <= 0.0:
            self.raiseError("invalid update_rate")
        return rate

    def _statistics(self, prefix: str) -> tuple[float, float, float]:
        n = self._field(f"{prefix}_noise_density")
        w = self._field(f"{prefix}_random_walk")
        if n <= 0.0:
            self.raiseError(f"invalid {prefix}_noise_density")
        if w <= 0.0:
            self.raiseError(f"invalid {prefix}_random_walk")
        return n / math.sqrt(1.0 / self.getUpdateRate()), w, n

    def getAccelerometerStatistics(self) -> tuple[float, float, float]:
        return self._statistics("accelerometer")

    def getGyroStatistics(self) -> tuple[float, float, float]:
        return self._statistics("gyroscope")

    def printDetails(self) -> dict:
        """What ``printDetails`` reads (it prints them), as a dict."""
        return {"update_rate": self.getUpdateRate(),
                "accel": self.getAccelerometerStatistics(),
                "gyro": self.getGyroStatistics(), "rostopic": self.getRosTopic()}


class ImuCalibAccel:
    """``imu_calib::AccelCalib`` loading a calib_file and applying it, as modelled above."""

    def __init__(self, text: str) -> None:
        node = yaml.safe_load(text)
        sm, bias = node["SM"], node["bias"]
        assert isinstance(sm, list) and len(sm) == 9
        assert isinstance(bias, list) and len(bias) == 3
        self.SM = np.zeros((3, 3))
        for i in range(9):
            self.SM[i // 3, i % 3] = float(sm[i])
        self.bias = np.array([float(b) for b in bias])

    def apply(self, raw: np.ndarray) -> np.ndarray:
        """``corrected = SM * raw - bias`` for each row of ``raw`` (N, 3)."""
        return np.asarray(raw, dtype=float) @ self.SM.T - self.bias


@functools.cache
def _noise_text() -> str:
    from gyrocal.calib.allan import characterise_noise
    from gyrocal.calib.noise_sim import NoiseModel, simulate_still

    s = simulate_still(np.random.default_rng(6), 60.0, model=NoiseModel(
        noise_density=(1.5e-4, 1.7e-4, 1.6e-4), rate_random_walk=(2e-5,) * 3))
    return json.dumps(characterise_noise(s.rate, 200.0).with_meta(source="simulation").to_dict())


def noise_file(directory: Path) -> Path:
    """A gyrocal-noise document of a 60 s simulated still gyro at 200 Hz, written in
    ``directory`` (for the exports that take ``--noise``)."""
    p = Path(directory) / "noise.json"
    p.write_text(_noise_text())
    return p
