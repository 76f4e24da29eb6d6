"""Several sensors on one plate: one protocol, one recording and one calibration per sensor.

A lab or a line mounts several boards on the gimbal's plate (different I²C addresses or buses,
different models) and runs the protocol once. The runner (:class:`gyrocal.kit.protocol.Runner`)
drains every sensor's FIFO in each loop iteration; a :class:`RecordingGroup` writes each
sensor's samples into its own Recording v1 (the encoder rows and segments go to all of them), so
every existing reader (``estimate``, ``report``, ``track``, the exports, other tools that read
the format) works on each sensor's recording unchanged. A sensor that fails (it stops
answering, or its data fail a check on every repeat) fails alone: its recording is closed
incomplete with the reason in its manifest's ``failure``, and the others go on.

Layout of ``gyrocal calibrate --out DIR`` with several sensors::

    DIR/NAME/recording/        Recording v1 of sensor NAME (manifest "plate": its place)
    DIR/NAME/calibration.json  its calibration (absent if it failed)
    DIR/NAME/report.html       its report (with the plot extra)
    DIR/summary.json           every sensor's verdict and exit code
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gyrocal.kit.recording import RecordingWriter

__all__ = ["PASSED", "RecordingGroup", "SensorOutcome", "calibrate_plate", "describe_plate",
           "history_targets", "plate_exit_code", "run_plate", "sensor_labels",
           "summary_document"]

#: The verdict of a sensor that passed.
PASSED = "passed"


class RecordingGroup:
    """One :class:`~gyrocal.kit.recording.RecordingWriter` per sensor, behind the writer
    interface :class:`~gyrocal.kit.backlog.Backlog` feeds.

    Parameters
    ----------
    writers : sequence of RecordingWriter
        One per sensor, in the runner's sensor order; their manifests share ``protocol``.

    Notes
    -----
    :attr:`manifest` is the first writer's: the backlog reads it to merge ``protocol`` fields,
    which are the same in every recording.
    """

    def __init__(self, writers: Sequence[RecordingWriter]) -> None:
        if not writers:
            raise ValueError("a RecordingGroup needs at least one writer")
        self.writers = list(writers)
        #: Sensors that failed, by index: the reason (also in their manifest's ``failure``).
        self.failed: dict[int, str] = {}

    @property
    def manifest(self) -> dict[str, Any]:
        """The first writer's manifest (the shared ``protocol`` is the same in all)."""
        return self.writers[0].manifest

    def _alive(self) -> list[RecordingWriter]:
        return [w for k, w in enumerate(self.writers) if k not in self.failed]

    def append_imus(self, rows: Sequence[Any]) -> None:
        """One loop iteration's rows: ``(t, rate, temperature_c, accel)`` or None per sensor."""
        for k, (w, r) in enumerate(zip(self.writers, rows, strict=True)):
            if r is not None and k not in self.failed:
                w.append_imu(*r)

    def append_encoder(self, t: Any, motor: Any, angle: Any) -> None:
        """Encoder rows, to every sensor's recording still open."""
        for w in self._alive():
            w.append_encoder(t, motor, angle)

    def append_segment(self, seg: Any) -> None:
        """A finished segment, to every sensor's recording still open."""
        for w in self._alive():
            w.append_segment(seg)

    def update_manifest(self, **fields: Any) -> None:
        """Merge ``fields`` into every open recording's manifest."""
        for w in self._alive():
            w.update_manifest(**fields)

    def fail(self, k: int, message: str, exit_code: int) -> None:
        """Close sensor ``k``'s recording incomplete, its manifest's ``failure`` saying why
        (``{"message", "exit_code"}``)."""
        if k in self.failed:
            return
        self.failed[k] = message
        w = self.writers[k]
        w.manifest["failure"] = {"message": message, "exit_code": int(exit_code)}
        w.close(complete=False)

    def finish(self) -> None:
        """Mark every recording still open complete (a clean finish) and close it."""
        for w in self._alive():
            w.finish()

    def close(self, complete: bool = False) -> None:
        """Close every recording (incomplete unless ``complete``)."""
        for w in self._alive():
            w.close(complete=complete)

    def __enter__(self) -> RecordingGroup:
        return self

    def __exit__(self, exc_type: object, exc: object, tb: object) -> None:
        for w in self.writers:
            w.close(complete=False)


@dataclass(frozen=True)
class SensorOutcome:
    """What became of one sensor of a plate.

    Attributes
    ----------
    name : str
        Its ``[[imu]]`` name (its directory under the run's).
    model : str
        Its configured model.
    verdict : str
        :data:`PASSED`, or what failed it (the message for the user).
    exit_code : int
        What ``gyrocal calibrate`` would exit with for this sensor alone (0 passed, 3 not
        consistent, 4 hardware, 5 a check, 6 implausible, ...).
    calibration : dict or None
        Its calibration document, if one was fitted.
    """

    name: str
    model: str
    verdict: str
    exit_code: int
    calibration: dict[str, Any] | None = None

    @property
    def passed(self) -> bool:
        """True when this sensor's calibration passed."""
        return self.exit_code == 0


def plate_exit_code(outcomes: Sequence[SensorOutcome]) -> int:
    """0 when every sensor passed, else the exit code of the first that did not (config
    order); the summary names each."""
    return next((o.exit_code for o in outcomes if not o.passed), 0)


def summary_document(outcomes: Sequence[SensorOutcome]) -> dict[str, Any]:
    """``DIR/summary.json`` (and ``calibrate --json`` with several sensors): every sensor's
    verdict, exit code and calibration."""
    return {"format": "gyrocal-plate-summary", "version": 1,
            "passed": all(o.passed for o in outcomes),
            "exit_code": plate_exit_code(outcomes),
            "sensors": [{"name": o.name, "model": o.model, "verdict": o.verdict,
                         "exit_code": o.exit_code, "calibration": o.calibration}
                        for o in outcomes]}


def calibrate_plate(dirs: Sequence[Path], names: Sequence[str], models: Sequence[str],
                    method: str, *, sources: Sequence[str], allow_implausible: bool = False,
                    report: bool = False, force: bool = False, title: str = "") -> list[
                        SensorOutcome]:
    """Fit each sensor's recording of a plate run and write its calibration (and report).

    Parameters
    ----------
    dirs : sequence of Path
        Each sensor's directory (``NAME/``), holding its ``recording/``.
    names, models : sequence of str
        Each sensor's name and configured model.
    method : str
        The estimator (``protocol.method``).
    sources : sequence of str
        Each calibration's ``source`` (where its recording will be).
    allow_implausible, report, force, title
        As for ``gyrocal calibrate``.

    Returns
    -------
    list of SensorOutcome
        One per sensor, in order. A sensor that failed during the run, or whose fit fails,
        gets its reason and exit code; nothing here raises for one sensor's failure.
    """
    from gyrocal.kit.errors import GyrocalError, HardwareError, exit_code_for
    from gyrocal.kit.fileio import atomic_write_text
    from gyrocal.kit.pipeline import check_plausible, estimate_recording
    from gyrocal.kit.recording import RecordingError, load_recording, read_manifest

    out = []
    for d, name, model, source in zip(dirs, names, models, sources, strict=True):
        failure = read_manifest(d / "recording").get("failure")
        if isinstance(failure, dict):
            out.append(SensorOutcome(name, model, f"failed during the run: {failure['message']}",
                                     int(failure["exit_code"])))
            continue
        try:
            rec = load_recording(d / "recording")
        except RecordingError as exc:  # written just now: the sensor gave nothing usable
            out.append(SensorOutcome(name, model, f"gave no usable data: {exc}",
                                     HardwareError.exit_code))
            continue
        try:
            est = estimate_recording(rec, method, source=source)
            cal = est.calibration
            check_plausible(cal, rec.sensor, allow=allow_implausible, recording=rec,
                            extracted=est.extracted)
            atomic_write_text(d / "calibration.json", cal.to_json() + "\n")
            if report:
                import sys

                from gyrocal.kit.report_html import write_optional_report

                failed = write_optional_report(rec, cal, est.extracted, d / "plots",
                                               title=f"{title} {name}",
                                               html_path=d / "report.html", force=force,
                                               written_already=f"{name}/calibration.json",
                                               calibration=str(Path(source).parent
                                                               / "calibration.json"))
                if failed:
                    print(f"gyrocal: warning: sensor {name}: {failed}", file=sys.stderr)
        except GyrocalError as exc:
            out.append(SensorOutcome(name, model, f"not calibrated: {exc}", exit_code_for(exc)))
            continue
        ok = cal.consistency is None or cal.consistency.ok
        out.append(SensorOutcome(
            name, model, PASSED if ok else "not consistent with the measured noise (chi2 test)",
            0 if ok else 3, cal.to_dict()))
    return out


def sensor_labels(label: str, names: Sequence[str]) -> list[str]:
    """Each sensor's label in the calibration history, from one ``--sensor-label`` (or
    ``history.sensor_label``) for the whole plate.

    ``NAME=LABEL,NAME=LABEL,...`` names every sensor's label (by its ``[[imu]]`` name); a plain
    ``LABEL`` labels each sensor ``LABEL/NAME`` (a batch and its places on the plate).

    Raises
    ------
    gyrocal.kit.history.HistoryError
        A pair that is not ``NAME=LABEL``, a name not on the plate, a sensor left without a
        label, or a label the history refuses (:func:`gyrocal.kit.history.check_label`).
    """
    from gyrocal.kit.history import HistoryError, check_label

    if "=" not in label:
        return [check_label(f"{label}/{n}", f"--sensor-label {label!r} for sensor {n!r}")
                for n in names]
    pairs: dict[str, str] = {}
    for item in label.split(","):
        name, sep, lab = item.partition("=")
        name = name.strip()
        if not sep or not name or name in pairs:
            raise HistoryError(f"--sensor-label {label!r}: give NAME=LABEL pairs separated by "
                               "commas, one per sensor on the plate "
                               f"({', '.join(names)}), or one LABEL for them all")
        if name not in names:
            raise HistoryError(f"--sensor-label names {name!r}, which is not on the plate; its "
                               f"sensors are {', '.join(names)}")
        pairs[name] = check_label(lab, f"--sensor-label for sensor {name!r}")
    missing = [n for n in names if n not in pairs]
    if missing:
        raise HistoryError(f"--sensor-label gives no label for {', '.join(missing)}: label "
                           "every sensor on the plate (NAME=LABEL,...)")
    return [pairs[n] for n in names]


def history_targets(target: Any, names: Sequence[str]) -> list[Any]:
    """One :class:`~gyrocal.kit.history.HistoryTarget` per sensor (:func:`sensor_labels`), or
    None for each when nothing is to be stored."""
    from dataclasses import replace

    if target is None:
        return [None] * len(names)
    return [replace(target, label=lab) for lab in sensor_labels(target.label, names)]


def run_plate(cfg: Any, args: Any, out: Path, work: Path, *, report: bool
              ) -> list[SensorOutcome]:
    """``gyrocal calibrate`` with several sensors on the plate: one run of the jig (every
    sensor into its own recording under ``work``), then each sensor fitted
    (:func:`calibrate_plate`), ``summary.json`` written, and ``work`` swapped into ``out``
    (when they differ) only once everything is written.

    Parameters
    ----------
    cfg : Config
        With ``[[imu]]`` sensors.
    args : argparse.Namespace
        The jig flags (:func:`gyrocal.kit.jig.run_jig`) and ``allow_implausible``, ``force``.
    out, work : Path
        Where the run goes, and where it is built (``out`` itself, or a directory beside it
        when ``--force`` replaces a run).
    report : bool
        Write each sensor's report.

    Returns
    -------
    list of SensorOutcome
        In the config's order.
    """

    from gyrocal.kit.fileio import atomic_write_json, built_beside
    from gyrocal.kit.jig import run_jig

    sensors = cfg.imus()
    names = [s["name"] for s in sensors]
    with built_beside(work, out):
        run_jig(cfg, args, work, work / "recording")
        outcomes = calibrate_plate(
            [work / n for n in names], names, [s["model"] for s in sensors],
            cfg["protocol"]["method"], sources=[str(out / n / "recording") for n in names],
            allow_implausible=args.allow_implausible, report=report, force=args.force,
            title=f"{out} (gyrocal calibrate)")
        atomic_write_json(work / "summary.json", summary_document(outcomes))
    return outcomes


def describe_plate(outcomes: Sequence[SensorOutcome], sensors: Sequence[dict[str, Any]],
                   out: Path) -> str:
    """The text ``gyrocal calibrate`` prints after a plate run: each sensor's verdict and
    calibration table (against its truth when emulated), then the count that passed."""
    from gyrocal.calib.model import GyroCalibration
    from gyrocal.kit.recording import read_manifest
    from gyrocal.kit.report import calibration_table

    lines = []
    for o, sensor in zip(outcomes, sensors, strict=True):
        at = f"0x{sensor['address']:02X}" if sensor["address"] else "its own address"
        lines.append(f"== sensor {o.name}: {sensor['model']} at {at} on bus "
                     f"{sensor['bus']}: "
                     f"{o.verdict.upper() if o.passed else 'FAILED: ' + o.verdict}")
        if o.calibration is not None:
            truth = read_manifest(out / o.name / "recording").get("truth")
            lines.append(calibration_table(GyroCalibration.from_dict(o.calibration), truth))
        lines.append("")
    passed = sum(o.passed for o in outcomes)
    names = ", ".join(o.name for o in outcomes)
    lines.append(f"plate: {passed} of {len(outcomes)} sensors passed; wrote {out}/NAME/ for each "
                 f"({names}) and {out / 'summary.json'}")
    return "\n".join(lines)
