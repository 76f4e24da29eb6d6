"""An independent sample-level Recording v1 generator for the full model g = A (m + b).

Written from the contract alone (DESIGN.md "Recording v1", hardware_docs/formats.md: the
manifest's ``gimbal.motors`` in chain order, base first; ``move`` segments for pose changes;
encoder angles cumulative and unwrapped), with scipy's rotations and plain numpy: nothing from
gyrocal's kit, drivers or calib (no writer, no emulator, no kinematics, no planner).

The gimbal is three servos in a serial chain, base to sensor, each turning about a link axis
``a_j`` given in the frame of the link before it (tilted off x, y, z: a gimbal that is not
machined square), and a sensor mount ``M``. The sensor's orientation in the base frame is
``Rot(a_0, θ_0) Rot(a_1, θ_1) Rot(a_2, θ_2) M``, so its angular velocity in the sensor frame is

    ω = Σ_j (Rot(a_{j+1}, θ_{j+1}) … Rot(a_2, θ_2) M)ᵀ a_j θ̇_j,

evaluated at every gyro sample from the servos' exact angles and rates. The gyro reads
``m = C ω − b`` plus white noise, with ``C = diag(1/scale) @ misalignment`` (the emulator's
``SensorTruth`` convention, so ``truth`` in the manifest has the same meaning), rounded to the
MPU-9250's 500 °/s LSB unless ``lsb`` is 0. The encoders read the true angle rounded to 4096
ticks a turn unless ``ticks`` is 0.

With ``accel_truth`` (an accelerometer truth, :func:`draw_accel`), ``imu.csv`` gains the optional
columns ``ax,ay,az``: the specific force ``g f`` (gravity in the sensor's true orientation, the
jig's accelerations left out) read through ``a = A⁻¹ (g f) − b`` plus white noise, ``A`` lower
triangular (the calibration's frame convention, so ``A`` and ``b`` are what a fit must return),
and the schedule ends with a tour of :data:`TOUR_POSES` (base and middle servo angles) with a
rest in each.

The pose schedule differs from gyrocal's planner (which poses at 45° or 90°, turns negative first
and moves one servo per pair): here every servo turns positive first, the poses are at
``pose_deg`` (default 60°) and ``-pose_deg``, and a pose may move two servos at once.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from tests.kit.contract_recording import _profile

TICKS = 4096
#: MPU-9250 at ±500 °/s: 65.5 LSB per °/s (PS-MPU-9250A-01 §3.1).
LSB_500DPS = np.radians(1 / 65.5)


def draw_sensor(seed: int, cross: float = 0.02, tilt_rad: float = 0.02, mount_rad: float = 0.05,
                extreme: bool = False) -> dict:
    """A sensor and a skewed gimbal: off-diagonal terms up to ``cross`` (the largest exactly
    ``cross``), scale 0.9–1.1, bias up to 0.1 rad/s, link axes tilted by up to ``tilt_rad``,
    the mount rotated by up to ``mount_rad``. With ``extreme``, the paper's extreme sensor
    instead (Section III: scale U(1.2, 2.0), |bias| U(0.1, 0.2) rad/s with either sign), drawn
    from a stream of its own so the rest of the draw is the same."""
    rng = np.random.default_rng([seed, 0x1DE])
    off = rng.uniform(-1, 1, (3, 3)) * (1 - np.eye(3))
    mis = np.eye(3) + cross * off / np.max(np.abs(off)) if cross else np.eye(3)
    links = [np.eye(3)[j] + rng.uniform(-tilt_rad, tilt_rad, 3) for j in range(3)]
    truth = {
        "scale": rng.uniform(0.9, 1.1, 3),
        "bias": rng.uniform(-0.1, 0.1, 3),
        "misalignment": mis,
        "links": [v / np.linalg.norm(v) for v in links],
        "mount": Rotation.from_rotvec(rng.uniform(-mount_rad, mount_rad, 3)).as_matrix(),
    }
    if extreme:
        ext = np.random.default_rng([seed, 0xE7])
        truth["scale"] = ext.uniform(1.2, 2.0, 3)
        truth["bias"] = ext.choice([-1.0, 1.0], 3) * ext.uniform(0.1, 0.2, 3)
    return truth


def sensor_rate(links: list, mount: np.ndarray, angles: np.ndarray, rates: np.ndarray,
                wobble: tuple[float, list] | None = None) -> np.ndarray:
    """Angular velocity in the sensor frame (module docstring) for angles and rates (N, 3).
    With ``wobble = (ε, [e_0, e_1, e_2])`` each link is tilted by ``ψ_j = ε sin θ_j`` about
    ``e_j`` (⊥ its axis, fixed to the link) after its joint's rotation, ``Rot(a_j θ_j)
    Rot(e_j ψ_j)``: the joint's rate in the sensor frame is then ``(W_j inner)ᵀ a_j θ̇_j +
    innerᵀ e_j ψ̇_j``."""
    n = angles.shape[0]
    out = np.zeros((n, 3))
    inner = np.broadcast_to(mount, (n, 3, 3)).copy()  # Rot_{j+1} … Rot_2 M, built inside out
    for j in (2, 1, 0):
        if wobble is not None:
            eps, e = wobble[0], wobble[1][j]
            tilted = Rotation.from_rotvec(eps * np.sin(angles[:, j:j + 1]) * e[None, :]
                                          ).as_matrix() @ inner
            out += (np.einsum("nki,k->ni", inner, e)
                    * (eps * np.cos(angles[:, j]) * rates[:, j])[:, None])
            inner = tilted
        out += np.einsum("nki,k->ni", inner, links[j]) * rates[:, j:j + 1]
        rot = Rotation.from_rotvec(angles[:, j:j + 1] * links[j][None, :]).as_matrix()
        inner = rot @ inner
    return out


#: Base and middle servo angles (degrees) of the accelerometer's tour: gravity then points along
#: the sensor's ±x, ±y, −z and the eight diagonals between them (besides +z at home).
TOUR_POSES = ((90, 0), (-90, 0), (180, 0), (0, 90), (0, -90), (45, 45), (-45, 45), (45, -45),
              (-45, -45), (135, 45), (-135, 45), (135, -45), (-135, -45))


def draw_accel(seed: int, cross: float = 0.01, noise: float = 0.03) -> dict:
    """An accelerometer truth: ``A`` lower triangular with scales 0.97–1.03 and off-diagonal
    terms up to ``cross``, bias up to 0.3 m/s², white noise ``noise`` m/s² per sample."""
    rng = np.random.default_rng([seed, 0xACC])
    A = np.diag(rng.uniform(0.97, 1.03, 3)) + np.tril(rng.uniform(-cross, cross, (3, 3)), -1)
    return {"matrix": A, "bias": rng.uniform(-0.3, 0.3, 3), "noise": noise}


def schedule(pose_deg: float, gravity: bool = False, tour: bool = False) -> list[tuple]:
    """``(kind, servo position or positions, direction or target angles, )`` steps; with
    ``gravity`` a last rest with the base a quarter turn from home (gravity along ±y); with
    ``tour`` a rest at each of :data:`TOUR_POSES`."""
    p = np.radians(pose_deg)
    steps: list[tuple] = []
    for s in range(3):  # home turns, positive first
        steps += [("rotate", s, 1), ("rotate", s, -1)]
    # posed turns: the middle servo with the inner one at +pose; the base with the middle at
    # -pose and the inner at +pose (two servos moved at once); back home after each
    for turn, target in ((1, (0.0, 0.0, p)), (0, (0.0, -p, p))):
        steps.append(("move", target))
        steps += [("rotate", turn, 1), ("rotate", turn, -1)]
        steps.append(("move", (0.0, 0.0, 0.0)))
    if gravity:
        steps += [("move", (np.pi / 2, 0.0, 0.0)), ("move", (0.0, 0.0, 0.0))]
    if tour:
        steps += [("move", (np.radians(a), np.radians(b), 0.0)) for a, b in TOUR_POSES]
        steps.append(("move", (0.0, 0.0, 0.0)))
    return steps


def default_plan_steps(rest: float = 1.0, pose_deg: float = 45.0) -> list[tuple]:
    """The pose schedule of gyrocal's default protocol as written out in its segments.csv
    (``gyrocal calibrate --sim``; hardware_docs/running.md, "The steps"), for ``steps`` of
    :func:`write_recording`: every servo turned negative first with rests; two posed pairs, the
    base turned with the middle, then the inner servo at ``pose_deg``, each turn following its
    pose move at once (no rest between); the base a quarter turn from home for a gravity rest.
    Only the schedule is copied, none of the planner's code."""
    p = np.radians(pose_deg)
    steps: list[tuple] = [("rest", rest)]
    for s in range(3):
        steps += [("rotate", s, -1), ("rest", rest), ("rotate", s, 1), ("rest", rest)]
    for moved in (1, 2):
        target = np.zeros(3)
        target[moved] = p
        steps += [("move", tuple(target)), ("rotate", 0, -1), ("rest", rest), ("rotate", 0, 1),
                  ("rest", rest), ("move", (0.0, 0.0, 0.0))]
    steps += [("move", (np.pi / 2, 0.0, 0.0)), ("rest", rest), ("move", (0.0, 0.0, 0.0))]
    return steps


def specific_force(links: list, mount: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Gravity (1 g, up) in the sensor frame at each row of ``angles`` (N, 3): ``Rᵀ up`` with
    ``R = Rot(a_0, θ_0) Rot(a_1, θ_1) Rot(a_2, θ_2) M`` and ``up`` servo 3's link axis (the jig
    stands with it vertical in the home pose, the servo the manifest lists with axis ``z``)."""
    R = np.broadcast_to(np.eye(3), (angles.shape[0], 3, 3))
    for j in range(3):
        R = R @ Rotation.from_rotvec(angles[:, j:j + 1] * links[j][None, :]).as_matrix()
    R = R @ mount
    return np.einsum("nki,k->ni", R, links[2])


def settled(rng: np.random.Generator, band: float, tick: float):  # type: ignore[no-untyped-def]
    """Where a servo commanded to an angle comes to rest: a function of the commanded angle
    (rad) giving the true rest angle less the commanded one, the rest angle uniform within
    ``band`` ticks (of ``tick`` rad) about the centre of the tick nearest the commanded angle,
    a new draw per call; 0 when ``band`` is 0.

    An X-series position loop sets the motor's PWM from the position error in encoder ticks
    (ROBOTIS-GIT/emanual ``_includes/en/dxl/control_table_position_pid_gain.md``, step 4: the
    feedforward and PID controller calculate the PWM output), with Position I Gain 0 by
    default (hardware-reference §5, addresses 80–84): within a tick or two of the goal the PWM
    cannot turn the geared shaft against its friction, so it stops where friction holds it,
    anywhere within its tick, and another approach stops elsewhere (an XL430-W250 stopping
    4–5 ticks short of its goal with the default gains, answers.ros.org question 303081;
    ROBOTIS on an XH540 holding a goal: Present Position moves ±3 pulses in the gears' 0.25°
    backlash, forum.robotis.com thread 7582). Nothing puts the shaft on the tick grid.
    """
    def offset(angle: float) -> float:
        if not band:
            return 0.0
        return float((np.round(angle / tick) + band * rng.uniform(-0.5, 0.5)) * tick - angle)

    return offset


def speed_ripple(rng: np.random.Generator, fraction: float, speed: float,
                 components: int = 12, band_hz: tuple[float, float] = (1.0, 20.0)):  # type: ignore[no-untyped-def]
    """Speed ripple of one turn or move: a function of the time since its start ``τ``, the
    trapezoid's rate as a fraction of ``speed`` ``u(τ)`` and its derivative ``u̇(τ)``, giving
    the angle perturbation ``p = u g`` and its rate ``ṗ = u̇ g + u ġ`` (rad, rad/s), with
    ``g(τ) = Σ_k A_k sin(ω_k τ + φ_k)`` the sum of ``components`` sines at frequencies uniform
    in ``band_hz``, random phases, and amplitudes that give a rate ripple of RMS ``fraction ×
    speed`` while cruising (``A_k ω_k = fraction · speed · √(2/K)``). ``p`` vanishes at rest, so
    the turn still ends where its position loop stops it.

    A servo does not turn at a constant speed: the paper's simulation adds rotation noise of 5 %
    of the speed ("to simulate vibration during operation"), and its corrected readings still
    fluctuate with "motor speed instability" (both Section III-A, "Simulation Under Normal
    Conditions"). Gear meshes,
    commutation and the velocity loop put it at a few hertz to tens of hertz at calibration
    speeds; the band here is a plain choice within that, not a model of one servo.
    """
    if not fraction:
        return lambda tau, u, du: (0.0, 0.0)
    w = 2 * np.pi * rng.uniform(*band_hz, components)
    phase = rng.uniform(0, 2 * np.pi, components)
    amp = fraction * speed * np.sqrt(2.0 / components) / w

    def wiggle(tau: np.ndarray, u: np.ndarray, du: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        arg = np.outer(tau, w) + phase
        g, dg = np.sin(arg) @ amp, np.cos(arg) @ (amp * w)
        return u * g, du * g + u * dg

    return wiggle


def _acceleration(tau: np.ndarray, speed: float, delta: float, accel: float) -> np.ndarray:
    """The trapezoid's acceleration (rad/s², signless) at ``tau`` after its start, for a move
    of ``|delta|`` rad (:func:`~tests.kit.contract_recording._profile`'s shape)."""
    _, _, end = _profile(np.zeros(1), speed, abs(delta) / (2 * np.pi), accel)
    ramp = speed / accel
    return np.where((tau < 0) | (tau > end), 0.0,
                    np.where(tau < ramp, accel, np.where(tau > end - ramp, -accel, 0.0)))


def flicker_noise(rng: np.random.Generator, B: float, rate_hz: float, n: int) -> np.ndarray:
    """``n`` samples (n, 3) at ``rate_hz`` of flicker noise of one-sided spectral density
    ``(B²/π)/f`` and no mean, made by shaping white noise's spectrum (periodic over the ``n``
    samples): Allan deviation ``sqrt(2 ln 2) · sqrt(B²/π) ≈ 0.664 B`` (NBS TN 394; IEEE Std 952
    Annex C)."""
    dt = 1.0 / rate_hz
    f = np.fft.rfftfreq(n, dt)
    amp = np.zeros_like(f)
    amp[1:] = np.sqrt(B**2 / np.pi / f[1:] * n / (2 * dt))
    z = (rng.standard_normal((3, f.size)) + 1j * rng.standard_normal((3, f.size))) / np.sqrt(2)
    return np.fft.irfft(z * amp, n, axis=1).T


def write_recording(path, *, seed: int = 0, cross: float = 0.02, noise: float = 2.5e-3,
                    odr: float = 200.0, enc_hz: float = 100.0, speed: float = 4.0,
                    turns: int = 2, accel: float = 10.0, rest: float = 0.8,
                    move_speed: float = 2.0, pose_deg: float = 60.0, ticks: int = TICKS,
                    lsb: float = LSB_500DPS, ids: tuple = (11, 12, 13),
                    g_sensitivity: np.ndarray | None = None, steps: list | None = None,
                    hold: float = 0.06, bias_walk: float = 0.0, bias_flicker: float = 0.0,
                    wobble_rad: float = 0.0, hold_band: float = 0.0, ripple: float = 0.0,
                    temp_ramp: tuple[float, float] | None = None,
                    tempco: tuple[float, float, float] = (0.0, 0.0, 0.0),
                    accel_truth: dict | None = None, gravity_m_s2: float = 9.80665,
                    tour: bool = True, extreme: bool = False) -> dict:
    """Write a Recording v1 directory at ``path``; returns the truth (``draw_sensor``). With
    ``g_sensitivity`` (3×3, rad/s per g) the reading gains ``G f`` (``f`` from
    :func:`specific_force`) and the schedule a gravity rest. ``steps`` replaces the schedule
    (:func:`schedule`, a rest before every step) by steps laid out as given:
    ``("rest", seconds)``, ``("rotate", servo, ±1)``, ``("move", target angles)``
    (e.g. :func:`default_plan_steps`); there a move's segment lasts ``hold`` seconds past the
    servo's arrival (a runner waits for the servo to report it, then commands the next step:
    about 60 ms in gyrocal's emulated runs), the only still time before a turn that follows it.
    With ``bias_walk`` (rad/s/√s) the bias wanders as a random walk from ``truth["bias"]``; the
    truth then holds the walk at every gyro sample as ``bias_walk`` (n, 3), the bias being
    ``bias + bias_walk``. With ``bias_flicker`` (``B``, rad/s) the bias also carries flicker
    noise (:func:`flicker_noise`: one-sided density ``B²/π / f``, Allan floor ``0.664 B``), made
    over four hours with the recording at their start; the truth then holds it at every gyro
    sample as ``bias_flicker`` (n, 3) and its mean over the hour from the start as
    ``bias_flicker_hour`` (3,). With ``wobble_rad`` (``ε``) each link nods by ``ε sin θ_j``
    about an axis drawn perpendicular to its own (:func:`sensor_rate`; the gyro only, the
    accelerometer's force is left rigid); the axes are ``truth["wobble_axes"]``. With
    ``hold_band`` (a fraction of an encoder tick) every servo comes to rest, at the start and
    after each move and turn, at a true angle drawn uniformly within ``hold_band`` ticks about
    the centre of its goal's tick (the tick nearest the commanded angle), each rest its own
    draw: a position loop stops where friction holds the shaft, not on the tick grid
    (:func:`settled`); 0 stops every servo exactly on its commanded angle. With ``ripple``
    (a fraction) every turn and move carries speed ripple of that RMS fraction of its speed
    (:func:`speed_ripple`), which the gyro and the encoder both see; 0 turns at exactly the
    trapezoid's speed. With
    ``temp_ramp`` (°C at the start and the end) the die temperature
    ramps linearly (written in the ``temp`` column) and the bias follows it,
    ``bias + tempco (T − T_start)``. With ``accel_truth`` (:func:`draw_accel`) the
    accelerometer's columns and (unless ``tour`` is false) the tour (module docstring), gravity
    ``gravity_m_s2`` also written to the manifest's ``site``; an ``accel_truth`` with a
    ``reading`` (a function of the specific force in g giving the reading in g, such as an
    emulated accelerometer's) reads through it instead. With ``extreme`` the sensor is the
    paper's extreme one (:func:`draw_sensor`)."""
    truth = draw_sensor(seed, cross, extreme=extreme)
    rng = np.random.default_rng([seed, 0x5A3])
    path = Path(path)
    path.mkdir(parents=True)
    segs: list[tuple] = []  # (kind, motor index or None, direction, speed, t0, t1, [(j, Δθ)])
    t = 0.0
    pose = np.zeros(3)
    settle = settled(np.random.default_rng([seed, 0x401D]), hold_band,
                     2 * np.pi / (ticks or TICKS))
    start = np.array([settle(0.0) for _ in range(3)])  # where each servo rests at the start
    off = start.copy()  # each servo's true angle at rest less its commanded one
    _, _, turn_time = _profile(np.zeros(1), speed, turns, accel)
    ripple_rng = np.random.default_rng([seed, 0x919])
    with_tour = tour and accel_truth is not None
    plan = steps if steps is not None else [
        x for step in schedule(pose_deg, gravity=g_sensitivity is not None, tour=with_tour)
        for x in (("rest", rest), step)]
    for step in plan:
        if step[0] == "rest":
            segs.append(("rest", None, 0, 0.0, t, t + step[1], []))
            t += step[1]
        elif step[0] == "rotate":
            _, s, d = step
            new = settle(pose[s])  # whole turns: back to the same tick
            segs.append(("rotate", s, d, speed, t, t + turn_time,
                         [(s, d * 2 * np.pi * turns + new - off[s],
                           speed_ripple(ripple_rng, ripple, speed))]))
            off[s] = new
            t += turn_time
        else:
            target = np.asarray(step[1])
            new = {j: settle(target[j]) for j in range(3) if target[j] != pose[j]}
            moving = [(j, target[j] - pose[j] + new[j] - off[j]) for j in new]
            durations = []
            for j, delta in moving:
                turns_j = abs(delta) / (2 * np.pi)
                _, _, dur = _profile(np.zeros(1), move_speed, turns_j, accel)
                segs.append(("move", j, int(np.sign(delta)), move_speed, t, t + dur,
                             [(j, delta, speed_ripple(ripple_rng, ripple, move_speed))]))
                durations.append(dur)
            if steps is not None:
                segs[-len(moving):] = [sg[:5] + (sg[5] + hold,) + sg[6:]
                                       for sg in segs[-len(moving):]]
                durations.append(max(durations) + hold)
            t += max(durations)
            pose = target.copy()
            off[list(new)] = list(new.values())
    segs.append(("rest", None, 0, 0.0, t, t + rest, []))
    t_end = t + rest
    ts = np.arange(0.0, t_end, 1 / odr)
    te = np.arange(0.0, t_end, 1 / enc_hz)

    def motion(times):
        ang = np.broadcast_to(start, (times.size, 3)).copy()
        rate = np.zeros((times.size, 3))
        for _, _, _, sp, t0, _, parts in segs:
            for j, delta, wiggle in parts:
                a, r, _ = _profile(times - t0, sp, abs(delta) / (2 * np.pi), accel)
                p, dp = wiggle(times - t0, r / sp, _acceleration(times - t0, sp, delta, accel) / sp)
                ang[:, j] += np.sign(delta) * (np.where(times >= t0, a, 0.0) + p)
                rate[:, j] += np.sign(delta) * (r + dp)
        return ang, rate

    ang, rate = motion(ts)
    wobble = None
    if wobble_rad:
        wrng = np.random.default_rng([seed, 0x30B])
        axes = [np.cross(a, wrng.standard_normal(3)) for a in truth["links"]]
        truth["wobble_axes"] = [v / np.linalg.norm(v) for v in axes]
        wobble = (wobble_rad, truth["wobble_axes"])
    omega = sensor_rate(truth["links"], truth["mount"], ang, rate, wobble)
    C = np.diag(1 / truth["scale"]) @ truth["misalignment"]
    m = omega @ C.T - truth["bias"] + noise * rng.standard_normal(omega.shape)
    temp = None
    if temp_ramp is not None:
        temp = np.linspace(temp_ramp[0], temp_ramp[1], ts.size)
        m = m - np.outer(temp - temp_ramp[0], np.asarray(tempco, dtype=float))
    if bias_walk:
        steps = np.random.default_rng([seed, 0xB1A5]).standard_normal(omega.shape)
        truth["bias_walk"] = np.cumsum(steps, axis=0) * bias_walk / np.sqrt(odr)
        m = m - truth["bias_walk"]
    if bias_flicker:
        hours = flicker_noise(np.random.default_rng([seed, 0xF11C]), bias_flicker, odr,
                              int(4 * 3600 * odr))
        truth["bias_flicker"] = hours[: ts.size]
        truth["bias_flicker_hour"] = hours[: int(3600 * odr)].mean(axis=0)
        m = m - truth["bias_flicker"]
    if g_sensitivity is not None:
        m = m + specific_force(truth["links"], truth["mount"], ang) @ np.asarray(
            g_sensitivity).T
    if lsb:
        m = np.round(m / lsb) * lsb
    cols = m
    if accel_truth is not None:
        force = gravity_m_s2 * specific_force(truth["links"], truth["mount"], ang)
        if "reading" in accel_truth:
            a = gravity_m_s2 * np.asarray(accel_truth["reading"](force / gravity_m_s2))
        else:
            a = (np.linalg.solve(accel_truth["matrix"], force.T).T - accel_truth["bias"]
                 + accel_truth["noise"] * rng.standard_normal(force.shape))
        cols = np.column_stack([m, np.full(m.shape[0], np.nan), a])
    enc, _ = motion(te)
    if ticks:
        enc = np.round(enc / (2 * np.pi / ticks)) * (2 * np.pi / ticks)
    with open(path / "imu.csv", "w") as f:
        f.write("t,gx,gy,gz,temp\n" if accel_truth is None else "t,gx,gy,gz,temp,ax,ay,az\n")
        for i, (ti, row) in enumerate(zip(ts, m, strict=True)):
            tc = "" if temp is None else f"{temp[i]:.4f}"
            line = f"{ti:.6f},{row[0]:.10g},{row[1]:.10g},{row[2]:.10g},{tc}"
            if accel_truth is not None:
                r = cols[i]
                line += f",{r[4]:.10g},{r[5]:.10g},{r[6]:.10g}"
            f.write(line + "\n")
    with open(path / "encoder.csv", "w") as f:
        f.write("t,motor,angle\n")
        for i in range(te.size):
            for j in range(3):
                f.write(f"{te[i]:.6f},{ids[j]},{enc[i, j]:.12g}\n")
    with open(path / "segments.csv", "w") as f:
        f.write("index,kind,motor,direction,speed,t_start,t_end\n")
        for i, (kind, j, d, sp, t0, t1, _) in enumerate(segs):
            motor = "" if j is None else ids[j]
            f.write(f"{i},{kind},{motor},{d},{sp},{t0:.6f},{t1:.6f}\n")
    manifest = {
        "format": "gyrocal-recording", "version": 1, "created": "2026-01-01T00:00:00Z",
        "sensor": {"model": "mpu9250", "odr_hz": odr, "full_scale_dps": 500,
                   "sensitivity_rad_s_per_lsb": lsb or LSB_500DPS},
        "gimbal": {"motors": [{"id": ids[j], "model": "XM430-W350", "axis": "xyz"[j]}
                              for j in range(3)]},
        "protocol": {"name": "contract-full", "model": "full"},
        "complete": True,
        "truth": {"scale": truth["scale"].tolist(), "bias": truth["bias"].tolist(),
                  "misalignment": truth["misalignment"].tolist()},
    }
    if accel_truth is not None:
        manifest["site"] = {"gravity_m_s2": gravity_m_s2}
    (path / "manifest.json").write_text(json.dumps(manifest), encoding="utf-8")
    return truth
