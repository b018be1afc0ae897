"""Tests of the simulator (dynid.sim.simulator) and its effect catalogue (dynid.sim.effects).

Each effect is switched on alone on a short UR5 run with exact sensors, and the torque it leaves is
checked against the effect's own model, computed here from the states the simulator reports.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import replace
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from dynid.cli import main
from dynid.exceptions import DataError, ShapeError, UsageError
from dynid.optim.trajectory import FourierTrajectory, SampledTrajectory
from dynid.sim.effects import EFFECTS, parse_effects
from dynid.sim.simulator import (
    NoiseModel,
    SimulationResult,
    build_truth,
    perturb_params,
    simulate,
    truth_path,
    write_simulation,
)

DURATION = 2.0
EXACT = 1e-9


@pytest.fixture(scope="module")
def robot():
    from dynid.symbolic import load_robot

    return load_robot("ur5")


@pytest.fixture(scope="module")
def trajectory() -> FourierTrajectory:
    """A 2 s Fourier trajectory well inside the UR5's limits, with velocity reversals on every joint."""
    rng = np.random.default_rng(7)
    a = rng.normal(scale=0.25, size=(3, 6))
    b = rng.normal(scale=0.25, size=(3, 6))
    return FourierTrajectory(a=a, b=b, c=np.array([0.0, -1.2, 1.0, -1.0, 0.5, 0.0]), base_freq=0.5)


def run(robot, trajectory, **kwargs) -> SimulationResult:
    kwargs.setdefault("noise", NoiseModel.off())
    kwargs.setdefault("friction", "none")
    return simulate(robot, trajectory, duration=DURATION, **kwargs)


def rnea(robot, res: SimulationResult) -> np.ndarray:
    """Inverse dynamics of ``robot`` (its own parameters, armature and gravity) on the true states."""
    model = robot.pin_model
    data = model.createData()
    return np.array(
        [
            pin.rnea(model, data, q, dq, ddq)
            for q, dq, ddq in zip(res.q_true, res.dq_true, res.ddq_true, strict=True)
        ]
    )


def residual(robot, res: SimulationResult) -> np.ndarray:
    """Drive torque minus the nominal model's inverse dynamics on the true states (N m)."""
    return res.tau_drive - rnea(robot, res)


@pytest.fixture(scope="module")
def plain(robot, trajectory) -> SimulationResult:
    return run(robot, trajectory)


# ---------------------------------------------------------------------------- the rigid truth
def test_no_effect_no_noise_torque_is_rnea_of_true_states(robot, trajectory, plain):
    assert plain.t.shape == (round(DURATION * 1000) + 1,)
    np.testing.assert_allclose(plain.tau, rnea(robot, plain), rtol=0, atol=EXACT)
    np.testing.assert_array_equal(plain.q, plain.q_true)  # exact encoders
    np.testing.assert_array_equal(plain.tau, plain.tau_drive)  # exact current sensor
    # A tracking controller, not a replay: the motion differs from the command, but not by much.
    err = np.abs(plain.q_true - plain.q_desired).max()
    assert 1e-6 < err < 1e-2
    assert plain.components == {}


def test_perturbed_truth_drives_the_robot(robot, trajectory):
    res = run(robot, trajectory, perturb=0.2, seed=4)
    params = res.truth.robot.params
    assert np.abs(params / np.where(robot.params == 0, 1, robot.params) - 1).max() > 0.05
    model = robot.pin_model
    data = model.createData()
    Y = [
        pin.computeJointTorqueRegressor(model, data, *s)
        for s in zip(res.q_true, res.dq_true, res.ddq_true, strict=True)
    ]
    np.testing.assert_allclose(res.tau, np.array(Y) @ params, rtol=0, atol=EXACT)
    assert np.abs(res.tau - np.array(Y) @ robot.params).max() > 0.1


def test_true_acceleration_is_consistent_with_the_motion(plain):
    # The reported ddq is the instantaneous acceleration: the trapezoid rule integrates it to the velocity
    # (after the first ticks, where the controller's torque still jumps from tick to tick).
    step = np.diff(plain.dq_true, axis=0)[10:] * 1000.0
    mean = 0.5 * (plain.ddq_true[11:] + plain.ddq_true[10:-1])
    np.testing.assert_allclose(step, mean, atol=0.02 * np.abs(plain.ddq_true).max())


@pytest.mark.parametrize("friction", ["linear", "seed", "stribeck"])
def test_friction_enters_as_a_torque(robot, trajectory, friction):
    res = run(robot, trajectory, friction=friction)
    fr = res.truth.friction
    r = residual(robot, res)
    np.testing.assert_allclose(r, res.components["friction"], rtol=0, atol=EXACT)
    dq = res.dq_true
    fast = np.abs(dq) > 0.2  # tanh(dq / eps) is 1 to rounding; outside the low-speed regions
    sign = np.sign(dq)
    kc = np.where(dq > 0, fr.kc_pos, fr.kc_neg)
    expected = kc * sign + fr.kv1 * dq + fr.kv2 * dq * np.abs(dq) + fr.kv3 * dq**3
    if friction == "stribeck":
        expected += fr.ks * np.exp(-((dq / fr.vs) ** 2)) * sign
    assert fast.sum() > 100
    np.testing.assert_allclose(r[fast], expected[fast], rtol=1e-9, atol=EXACT)


def test_seed_friction_has_per_direction_coulomb_and_joins_at_lambda(robot):
    truth = build_truth(robot, friction="seed")
    fr = truth.friction
    assert np.all(fr.kc_pos > fr.kc_neg) and np.all(fr.kv2 > 0) and np.all(fr.kv3 > 0)
    lam = fr.vs
    for side in (1.0, -1.0):
        below, _ = fr.torque(side * lam * (1 - 1e-9))
        above, _ = fr.torque(side * lam * (1 + 1e-9))
        np.testing.assert_allclose(below, above, rtol=1e-6)
    # Negative slope in the low-speed region: more friction just after breakaway than at lambda.
    near0, _ = fr.torque(np.full(robot.n, 10 * fr.eps))
    at_lam, _ = fr.torque(lam)
    assert np.all(near0 > at_lam)


def test_seed_friction_is_what_the_friction_layer_fits(robot):
    # The truth's seed model has the form SeedFriction identifies: its fit on the truth curve returns it.
    from dynid.identify.friction import SeedFriction

    fr = build_truth(robot, friction="seed").friction
    dq = np.random.default_rng(0).uniform(-1.5, 1.5, 4000)
    dq = dq[np.abs(dq) > 20 * fr.eps]  # outside the tanh smoothing of sign(dq)
    j = 1
    torque = fr.torque(np.outer(dq, np.ones(robot.n)))[0][:, j]
    fitted = SeedFriction().fit(dq, torque).coef_
    truth = [fr.kc_pos[j], fr.kc_neg[j], fr.kv1[j], fr.kv2[j], fr.kv3[j], fr.kc_pos[j] + fr.ks[j]]
    truth += [fr.kc_neg[j] + fr.ks[j], fr.vs[j]]
    np.testing.assert_allclose(fitted, truth, rtol=1e-4)


# ---------------------------------------------------------------------------- one test per effect
def test_offset_is_a_constant_shift(robot, trajectory, plain):
    res = run(robot, trajectory, effects="offset")
    offset = res.truth.effect("offset").offset
    np.testing.assert_allclose(
        res.tau - res.tau_drive, np.broadcast_to(offset, res.tau.shape), rtol=0, atol=EXACT
    )
    np.testing.assert_allclose(res.tau_drive, plain.tau_drive, atol=EXACT)  # the robot moved the same
    ratio = np.abs(offset) / res.truth.scales.torque
    assert np.all((ratio >= 0.01 - 1e-12) & (ratio <= 0.02 + 1e-12))


def test_offset_on_one_joint(robot, trajectory):
    res = run(robot, trajectory, effects="offset@3:2")
    shift = (res.tau - res.tau_drive).mean(axis=0)
    assert np.count_nonzero(shift) == 1 and shift[2] != 0
    assert 0.02 <= abs(shift[2]) / res.truth.scales.torque[2] <= 0.04 + 1e-12


def test_drive_gain_scales_the_measured_torque(robot, trajectory):
    res = run(robot, trajectory, effects="drive_gain")
    gain = res.truth.effect("drive_gain").gain
    np.testing.assert_allclose(res.tau, res.tau_drive * gain, rtol=1e-12, atol=EXACT)
    dev = np.abs(gain - 1)
    assert np.all((dev >= 0.025 - 1e-12) & (dev <= 0.05 + 1e-12))
    assert np.ptp(gain) > 0  # not a common gain


def test_delay_shifts_the_measured_torque(robot, trajectory):
    res = run(robot, trajectory, effects="delay:1.5")  # 6 ms
    lag = 6
    assert res.truth.effect("delay").delay[0] == pytest.approx(0.006)
    np.testing.assert_allclose(res.tau[lag:], res.tau_drive[:-lag], rtol=0, atol=1e-9)
    for j in range(robot.n):
        a = np.diff(res.tau[:, j])
        b = np.diff(res.tau_drive[:, j])
        lags = np.arange(-20, 21)
        core = b[20 : len(b) - 20]
        xc = [np.corrcoef(a[20 + k : len(a) - 20 + k], core)[0, 1] for k in lags]
        assert lags[int(np.argmax(xc))] == lag


def test_armature_adds_rotor_inertia(robot, trajectory):
    res = run(robot, trajectory, effects="armature")
    inertia = res.truth.effect("armature").inertia
    np.testing.assert_allclose(inertia, 0.05 * res.truth.scales.inertia)
    np.testing.assert_allclose(residual(robot, res), inertia * res.ddq_true, rtol=0, atol=EXACT)


def test_payload_adds_its_own_inverse_dynamics(robot, trajectory):
    res = run(robot, trajectory, effects="payload")
    effect = res.truth.effect("payload")
    assert effect.mass == pytest.approx(0.05 * robot.params[0::10].sum())
    assert effect.link == robot.n - 1
    # The payload's contribution: the regressor times the standard parameters of a point mass.
    delta = np.zeros(10 * robot.n)
    c = effect.position
    inertia_o = effect.mass * (np.dot(c, c) * np.eye(3) - np.outer(c, c))
    delta[10 * effect.link : 10 * effect.link + 10] = [
        effect.mass,
        *(effect.mass * c),
        inertia_o[0, 0],
        inertia_o[0, 1],
        inertia_o[1, 1],
        inertia_o[0, 2],
        inertia_o[1, 2],
        inertia_o[2, 2],
    ]
    model = robot.pin_model
    data = model.createData()
    contribution = np.array(
        [
            pin.computeJointTorqueRegressor(model, data, q, dq, ddq) @ delta
            for q, dq, ddq in zip(res.q_true, res.dq_true, res.ddq_true, strict=True)
        ]
    )
    np.testing.assert_allclose(residual(robot, res), contribution, rtol=0, atol=EXACT)


def test_base_tilt_rotates_gravity(robot, trajectory):
    res = run(robot, trajectory, effects="base_tilt:2")
    effect = res.truth.effect("base_tilt")
    g0 = np.asarray(robot.gravity)
    g1 = effect.gravity
    assert np.linalg.norm(g1) == pytest.approx(np.linalg.norm(g0))
    assert math.degrees(math.acos(g0 @ g1 / (g0 @ g0))) == pytest.approx(2.0)
    model = robot.pin_model
    data = model.createData()
    tilted = pin.Model(model)
    tilted.gravity.linear = g1
    tdata = tilted.createData()
    expected = np.array(
        [
            pin.computeGeneralizedGravity(tilted, tdata, q) - pin.computeGeneralizedGravity(model, data, q)
            for q in res.q_true
        ]
    )
    assert np.abs(expected).max() > 0.1
    np.testing.assert_allclose(residual(robot, res), expected, rtol=0, atol=EXACT)


def test_stribeck_is_a_low_speed_bump(robot, trajectory):
    res = run(robot, trajectory, effects="stribeck")
    effect = res.truth.effect("stribeck")
    dq = res.dq_true
    r = residual(robot, res)
    expected = effect.bump * np.exp(-((dq / effect.speed) ** 2)) * np.tanh(dq / effect.eps)
    np.testing.assert_allclose(r, expected, rtol=0, atol=EXACT)
    slow = (np.abs(dq) > 5 * effect.eps) & (np.abs(dq) < 0.2 * effect.speed)
    fast = np.abs(dq) > 4 * effect.speed
    assert slow.any() and fast.any()
    assert np.all(np.abs(r[slow]) > 0.9 * np.broadcast_to(effect.bump, r.shape)[slow])
    assert np.abs(r[fast]).max() < 1e-6 * effect.bump.max()


def test_load_friction_grows_with_the_drive_torque(robot, trajectory):
    res = run(robot, trajectory, effects="load_friction")
    effect = res.truth.effect("load_friction")
    dq, tau = res.dq_true, res.tau_drive
    r = residual(robot, res)
    fast = np.abs(dq) > 0.05
    driving = fast & (dq * tau > 0)
    back = fast & (dq * tau < 0)
    assert driving.sum() > 100 and back.sum() > 100
    np.testing.assert_allclose(r[driving], (0.05 * np.abs(tau) * np.sign(dq))[driving], rtol=1e-9, atol=EXACT)
    np.testing.assert_allclose(r[back], (0.025 * np.abs(tau) * np.sign(dq))[back], rtol=1e-9, atol=EXACT)
    assert np.all(effect.mu_drive == 0.05)


def test_temperature_lowers_the_friction_along_the_run(robot, trajectory):
    res = run(robot, trajectory, effects="temperature:3", friction="linear")
    fr = res.truth.friction
    base = fr.kc_pos * np.tanh(res.dq_true / fr.eps) + fr.kv1 * res.dq_true
    r = residual(robot, res)
    big = np.abs(base) > 0.5 * fr.kc_pos
    factor = np.where(big, r / np.where(big, base, 1.0), np.nan)
    expected = 1 - 0.9 * (1 - np.exp(-res.t / 60.0))
    for j in range(robot.n):
        np.testing.assert_allclose(factor[big[:, j], j], expected[big[:, j]], rtol=1e-9)
    assert expected[-1] < 0.975  # 2 s of a 60 s warm-up at 90 %: a 2.9 % drop


def test_cogging_peaks_at_the_gear_frequency(robot, trajectory):
    res = run(robot, trajectory, effects="cogging")
    effect = res.truth.effect("cogging")
    r = residual(robot, res)
    j = int(np.argmax(np.ptp(res.q_true, axis=0)))
    q, rj = res.q_true[:, j], r[:, j]
    # r is a function of the angle alone: resample it on a uniform angle grid and take its spectrum.
    order = np.argsort(q)
    qs, keep = np.unique(q[order], return_index=True)
    grid = np.linspace(qs[0], qs[-1], 8192)
    sampled = np.interp(grid, qs, rj[order][keep])
    spectrum = np.abs(np.fft.rfft(sampled - sampled.mean()))
    freq = np.fft.rfftfreq(grid.size, d=grid[1] - grid[0])  # cycles per rad
    span = grid[-1] - grid[0]
    first = freq[int(np.argmax(spectrum))]
    assert first == pytest.approx(effect.ratio / (2 * math.pi), abs=1.5 / span)
    second_band = freq > 1.5 * effect.ratio / (2 * math.pi)
    second = freq[second_band][int(np.argmax(spectrum[second_band]))]
    assert second == pytest.approx(2 * effect.ratio / (2 * math.pi), abs=1.5 / span)
    # And the amplitudes are the truth's (least squares on sin/cos of k N q).
    cols = [f(k * effect.ratio * q) for k in (1, 2) for f in (np.sin, np.cos)]
    coef = np.linalg.lstsq(np.column_stack(cols), rj, rcond=None)[0]
    np.testing.assert_allclose(np.hypot(coef[0::2], coef[1::2]), effect.amplitude[j], rtol=1e-6)
    np.testing.assert_allclose(effect.amplitude[:, 0], 0.01 * res.truth.scales.torque)


def test_coupled_friction_acts_on_the_sum_of_the_last_two_speeds(robot, trajectory):
    res = run(robot, trajectory, effects="coupled_friction")
    effect = res.truth.effect("coupled_friction")
    r = residual(robot, res)
    w = res.dq_true[:, -2] + res.dq_true[:, -1]
    g = effect.coulomb * np.tanh(w / effect.eps) + effect.viscous * w
    np.testing.assert_allclose(r[:, -2], g, rtol=0, atol=EXACT)
    np.testing.assert_allclose(r[:, -1], g, rtol=0, atol=EXACT)
    np.testing.assert_allclose(r[:, :-2], 0.0, atol=EXACT)
    # Not a function of either speed alone: same sign of dq_6, opposite friction.
    assert np.any(np.sign(g) != np.sign(res.dq_true[:, -1]))


def test_nonlinear_viscous_adds_square_and_cubic_terms(robot, trajectory):
    res = run(robot, trajectory, effects="nonlinear_viscous")
    effect = res.truth.effect("nonlinear_viscous")
    dq = res.dq_true
    np.testing.assert_allclose(
        residual(robot, res), effect.kv2 * dq * np.abs(dq) + effect.kv3 * dq**3, rtol=0, atol=EXACT
    )
    v = res.truth.scales.speed
    np.testing.assert_allclose(effect.kv2 * v**2, 0.02 * res.truth.scales.torque)


def test_elasticity_is_a_spring_between_motor_and_link(robot, trajectory):
    res = run(robot, trajectory, effects="elasticity@2")
    tr = res.truth.transmission
    assert tr.joints.tolist() == [1]
    k, d, b = tr.stiffness[0], tr.damping[0], tr.motor_inertia[0]
    link = rnea(res.truth.link_robot, res)
    spring = k * (res.theta[:, 1] - res.q_true[:, 1]) + d * (res.dtheta[:, 1] - res.dq_true[:, 1])
    np.testing.assert_allclose(link[:, 1], spring, rtol=0, atol=1e-9 * np.abs(spring).max())
    # The motor: drive torque = motor inertia x motor acceleration + spring torque.
    np.testing.assert_allclose(res.tau_drive[:, 1], b * res.ddtheta[:, 1] + spring, rtol=0, atol=EXACT)
    # Rigid joints stay rigid; the encoder of joint 2 reads the motor, deflected by tau / K from the link.
    np.testing.assert_allclose(res.tau_drive[:, [0, 2, 3, 4, 5]], link[:, [0, 2, 3, 4, 5]], atol=EXACT)
    np.testing.assert_array_equal(res.q[:, 1], res.theta[:, 1])
    deflection = res.q[:, 1] - res.q_true[:, 1]
    assert np.abs(deflection).max() > 1e-3
    np.testing.assert_allclose(deflection, spring / k, atol=0.05 * np.abs(deflection).max())
    assert k == pytest.approx(res.truth.scales.inertia[1] * (2 * math.pi * 10) ** 2)


def test_backlash_transmits_nothing_inside_the_gap(robot, trajectory):
    res = run(robot, trajectory, effects="backlash@1:4")
    tr = res.truth.transmission
    half = 0.5 * tr.gap[0]
    assert half == pytest.approx(2e-3)
    delta = res.theta[:, 0] - res.q_true[:, 0]
    link = rnea(res.truth.link_robot, res)[:, 0]
    inside = np.abs(delta) < half
    assert 5 < inside.sum() < inside.size - 5  # the teeth part where the torque changes sign
    np.testing.assert_allclose(link[inside], 0.0, atol=EXACT)
    contact = ~inside
    ddelta = res.dtheta[:, 0] - res.dq_true[:, 0]
    expected = tr.stiffness[0] * np.sign(delta) * (np.abs(delta) - half) + tr.damping[0] * ddelta
    np.testing.assert_allclose(link[contact], expected[contact], rtol=1e-9, atol=EXACT)


def test_every_effect_has_a_test():
    tested = {name.split("_test")[0] for name in globals() if name.startswith("test_")}
    names = " ".join(tested)
    for effect in EFFECTS:
        assert f"test_{effect}" in names, f"no test for the effect {effect}"


def test_all_effects_together_run(robot, trajectory):
    res = simulate(
        robot, trajectory, effects=",".join(EFFECTS), friction="seed", duration=DURATION, perturb=0.1
    )
    assert np.all(np.isfinite(res.tau)) and np.all(np.isfinite(res.q))
    assert np.abs(res.q_true - res.q_desired).max() < 0.05


# ---------------------------------------------------------------------------- truth and sensors
def test_perturbation_keeps_links_physical(robot):
    rng = np.random.default_rng(3)
    params = perturb_params(robot.params, 0.3, rng)
    assert not np.allclose(params, robot.params)
    for i in range(robot.n):
        inertia = pin.Inertia.FromDynamicParameters(params[10 * i : 10 * i + 10])
        assert inertia.mass > 0
        eig = np.linalg.eigvalsh(inertia.inertia)  # about the centre of mass
        assert eig.min() > 0
        assert eig[0] + eig[1] >= eig[2] * (1 - 1e-12)  # triangle inequality
        assert abs(inertia.mass / robot.params[10 * i] - 1) <= 0.3 + 1e-12


def test_encoder_and_current_quantisation(robot, trajectory):
    res = run(robot, trajectory, noise="off,encoder_bits=12,current_lsb=0.01")
    step = 2 * math.pi / 2**12
    counts = res.q / step
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)
    assert np.abs(res.q - res.theta).max() <= step / 2 + 1e-12
    lsb = 0.01 * res.truth.scales.torque
    np.testing.assert_allclose(res.tau / lsb, np.round(res.tau / lsb), atol=1e-6)
    assert np.all(np.abs(res.tau - res.tau_drive) <= lsb / 2 + 1e-12)


def test_noise_levels_and_colour(robot, trajectory):
    res = simulate(
        robot,
        trajectory,
        friction="none",
        duration=DURATION,
        noise="off,torque=0.01,coloured=0.02,colour=0.95",
    )
    e = (res.tau - res.tau_drive) / res.truth.scales.torque
    assert np.std(e) == pytest.approx(math.hypot(0.01, 0.02), rel=0.25)
    lag1 = np.mean([np.corrcoef(e[1:, j], e[:-1, j])[0, 1] for j in range(robot.n)])
    assert lag1 == pytest.approx(0.95 * 0.02**2 / (0.01**2 + 0.02**2), abs=0.1)


def test_seeds_repeat_and_differ(robot, trajectory):
    a = simulate(robot, trajectory, effects="drive_gain,cogging", duration=1.0, seed=5)
    b = simulate(robot, trajectory, effects="drive_gain,cogging", duration=1.0, seed=5)
    c = simulate(robot, trajectory, effects="drive_gain,cogging", duration=1.0, seed=6)
    np.testing.assert_array_equal(a.tau, b.tau)
    np.testing.assert_array_equal(a.q, b.q)
    assert not np.allclose(a.tau, c.tau)
    assert not np.allclose(a.truth.effect("drive_gain").gain, c.truth.effect("drive_gain").gain)
    # Same truth seed, other noise seed: the same robot with independent noise.
    d = simulate(robot, trajectory, effects="drive_gain,cogging", duration=1.0, seed=6, truth_seed=5)
    np.testing.assert_array_equal(a.truth.effect("drive_gain").gain, d.truth.effect("drive_gain").gain)
    assert not np.allclose(a.tau, d.tau)


def test_output_rate_decimates(robot, trajectory, plain):
    res = run(robot, trajectory, rate=250)
    np.testing.assert_allclose(res.t, plain.t[::4])
    np.testing.assert_allclose(res.tau, plain.tau[::4], atol=EXACT)


# ---------------------------------------------------------------------------- files
def test_write_data_and_sidecar(robot, trajectory, tmp_path):
    res = simulate(robot, trajectory, effects="offset,delay", duration=0.5, seed=2)
    data, sidecar = write_simulation(res, tmp_path / "d.csv")
    assert sidecar == truth_path(data) == tmp_path / "d.csv.truth.json"
    header = data.read_text().splitlines()[0].split(",")
    assert header == ["t", *(f"q_{j}" for j in range(1, 7)), *(f"tau_{j}" for j in range(1, 7))]
    truth = json.loads(sidecar.read_text())
    for key in ("params", "friction", "effects", "noise", "seed", "controller", "scales"):
        assert key in truth
    assert [e["name"] for e in truth["effects"]] == ["offset", "delay"]
    assert truth["effects"][0]["offset"] == pytest.approx(res.truth.effect("offset").offset.tolist())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.csv", "d.csv.truth.json"]
    umask = os.umask(0)
    os.umask(umask)
    assert data.stat().st_mode & 0o777 == sidecar.stat().st_mode & 0o777 == 0o666 & ~umask


def test_true_states_only_when_asked(robot, trajectory, tmp_path):
    res = simulate(robot, trajectory, duration=0.2)
    data, _ = write_simulation(res, tmp_path / "d.npz", true_states=True)
    with np.load(data) as archive:
        assert "dq_1" in archive.files and "ddq_6" in archive.files


# ---------------------------------------------------------------------------- bad input
def test_unknown_effect_lists_the_known_ones():
    with pytest.raises(
        UsageError, match=r"unknown effect 'wobble'; the known effects are offset, armature, .*"
    ):
        parse_effects("offset,wobble")


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("offset:abc", r"size of the effect 'offset:abc' is 'abc', not a number"),
        ("offset:-1", r"size of the effect 'offset' is -1.0; give a finite positive number"),
        ("offset:nan", r"size of the effect 'offset' is nan"),
        ("temperature:4", r"must stay below 3\.33"),
        ("elasticity@x", r"joint selector of the effect 'elasticity@x' is not @J or @J-K"),
        ("payload@2", r"the effect 'payload' acts on the whole arm and takes no joint selector"),
        ("offset,offset:2", r"the effect 'offset' is given twice"),
    ],
)
def test_bad_effect_values(spec, message):
    with pytest.raises(UsageError, match=message):
        parse_effects(spec)


def test_joint_selector_outside_the_robot(robot, trajectory):
    with pytest.raises(UsageError, match=r"selects joint 7; the robot 'ur5' has joints 1\.\.6"):
        run(robot, trajectory, effects="elasticity@7")


def test_temperature_needs_friction(robot, trajectory):
    with pytest.raises(UsageError, match=r"'temperature' drifts the friction coefficients"):
        run(robot, trajectory, effects="temperature", friction="none")


def test_bad_noise_settings():
    with pytest.raises(UsageError, match=r"unknown noise setting 'hum'; the known ones are torque"):
        NoiseModel.parse("hum=3")
    with pytest.raises(UsageError, match=r"colour is 1.0; give an AR\(1\) coefficient in \[0, 1\)"):
        NoiseModel.parse("colour=1")


def test_trajectory_for_another_robot(robot):
    seven = FourierTrajectory(a=np.zeros((2, 7)), b=np.zeros((2, 7)), c=np.zeros(7), base_freq=0.5)
    with pytest.raises(ShapeError, match=r"has 7 joints; the robot 'ur5' has 6"):
        simulate(robot, seven)


def test_trajectory_beyond_the_limits(robot):
    fast = FourierTrajectory(a=np.full((1, 6), 4.0), b=np.zeros((1, 6)), c=np.zeros(6), base_freq=0.5)
    with pytest.raises(UsageError, match=r"takes dq_1 to 4 rad/s at t = 0 s, beyond the limit 3.15 rad/s"):
        simulate(robot, fast)


def test_bad_rate_and_duration(robot, trajectory):
    with pytest.raises(UsageError, match=r"output rate 300 Hz does not divide the control rate 1000 Hz"):
        run(robot, trajectory, rate=300)
    with pytest.raises(UsageError, match=r"the duration is -1 s; give a positive duration"):
        simulate(robot, trajectory, duration=-1)


def test_sampled_trajectory_does_not_repeat(robot, trajectory):
    t, q, dq, ddq = trajectory.sample(1000.0)
    sampled = SampledTrajectory(t=t, q=q, dq=dq, ddq=ddq)
    res = simulate(robot, sampled, noise="off", friction="none")
    np.testing.assert_allclose(res.q_desired, q, atol=1e-12)
    with pytest.raises(UsageError, match=r"longer than the trajectory \(2 s\), which does not repeat"):
        simulate(robot, sampled, duration=3.0)


def test_missing_output_folder_writes_nothing(robot, trajectory, tmp_path):
    res = simulate(robot, trajectory, duration=0.1)
    with pytest.raises(DataError, match=r"for the output does not exist; create it"):
        write_simulation(res, tmp_path / "nowhere" / "d.csv")
    assert list(tmp_path.iterdir()) == []


def test_failed_sidecar_leaves_no_data_file(robot, trajectory, tmp_path):
    res = simulate(robot, trajectory, duration=0.1)
    (tmp_path / "d.csv.truth.json").mkdir()  # the sidecar cannot take its name
    with pytest.raises(OSError, match=r"d\.csv\.truth\.json"):
        write_simulation(res, tmp_path / "d.csv")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.csv.truth.json"]


# ---------------------------------------------------------------------------- command line
@pytest.fixture
def trajectory_file(trajectory, tmp_path) -> Path:
    path = tmp_path / "t.json"
    trajectory.save(path)
    return path


def test_cli_unknown_effect(trajectory_file, tmp_path, capsys):
    out = tmp_path / "d.csv"
    code = main(["simulate", "--robot", "ur5", "--trajectory", str(trajectory_file), "--effects", "wobble",
                 "--out", str(out)])  # fmt: skip
    assert code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown effect 'wobble'" in err and "nonlinear_viscous" in err
    assert not out.exists()


def test_cli_missing_folder(trajectory_file, tmp_path, capsys):
    code = main(["simulate", "--robot", "ur5", "--trajectory", str(trajectory_file), "--out",
                 str(tmp_path / "no" / "d.csv")])  # fmt: skip
    assert code == 2
    assert "does not exist" in capsys.readouterr().err


def test_cli_writes_data_and_truth(trajectory_file, tmp_path, capsys):
    out = tmp_path / "d.csv"
    code = main(["simulate", "--robot", "ur5", "--trajectory", str(trajectory_file), "--effects",
                 "offset,cogging@6:2", "--duration", "0.5", "--rate", "500", "--seed", "3", "--out", str(out)])  # fmt: skip
    assert code == 0
    assert "wrote" in capsys.readouterr().out
    lines = out.read_text().splitlines()
    assert len(lines) == 1 + 251
    truth = json.loads(truth_path(out).read_text())
    assert truth["seed"] == 3 and truth["sampling"]["rate_hz"] == 500
    assert [e["name"] for e in truth["effects"]] == ["offset", "cogging"]
    assert truth["effects"][1]["joints"] == [6] and truth["effects"][1]["value"] == 2.0


def test_cli_runs_three_periods_by_default(robot, tmp_path, capsys):
    from dynid.optim.trajectory import FourierTrajectory

    short = FourierTrajectory(a=np.full((1, 6), 0.02), b=np.zeros((1, 6)), c=np.array([0.0, -1.2, 1.0, -1.0, 0.5, 0.0]), base_freq=5.0)
    path = tmp_path / "t.json"
    short.save(path)
    for extra, periods in (([], 3), (["--periods", "2"], 2)):
        out = tmp_path / f"d{periods}.csv"
        code = main(["simulate", "--robot", "ur5", "--trajectory", str(path), "--rate", "100", "--out", str(out),
                     *extra])  # fmt: skip
        assert code == 0
        t = np.loadtxt(out, delimiter=",", skiprows=1, usecols=0)
        assert t[-1] == pytest.approx(periods / 5.0)
    # A trajectory saved with more periods keeps them.
    five = FourierTrajectory(a=short.a, b=short.b, c=short.c, base_freq=5.0, periods=5)
    five.save(tmp_path / "t5.json")
    code = main(["simulate", "--robot", "ur5", "--trajectory", str(tmp_path / "t5.json"), "--rate", "100",
                 "--out", str(tmp_path / "d5.csv")])  # fmt: skip
    assert code == 0
    assert np.loadtxt(tmp_path / "d5.csv", delimiter=",", skiprows=1, usecols=0)[-1] == pytest.approx(1.0)
    code = main(["simulate", "--robot", "ur5", "--trajectory", str(path), "--periods", "0", "--out",
                 str(tmp_path / "d0.csv")])  # fmt: skip
    assert code == 2 and "--periods is 0; give a whole number of at least 1" in capsys.readouterr().err
    assert not (tmp_path / "d0.csv").exists()


# ---------------------------------------------------------------------------- synthetic excitation
# Coefficients of the one random Fourier generator, recorded before the two generators were merged:
# the diagnosis' cases (whole-arm scaling about the case posture) and the regressor datasets
# (each joint scaled on its own) must keep drawing exactly these motions.
EXCITATIONS = {
    ("ur5", "case"): (
        [-0.08972417262407402, -0.012806589022348078, -0.08268187218159277, -0.04444031927816023,
         0.017183492226907463, -0.20289655222893674],
        [0.0, -1.2, 1.0, -1.0, 0.5, 0.0],
    ),
    ("ur5", "joint"): (
        [0.5790071132235814, -0.7586638486511877, 0.1927623970246147, -0.1628283145681508,
         -0.3000785135743055, -0.11819708351084215],
        [-0.0005516029716521315, -4.375501179619438e-06, 0.0001489106166283706, -0.00022862686216057202,
         0.0005182180880442467, 0.0006602579282799676],
    ),
    ("panda", "case"): (
        [-0.08085478809879336, -0.011540636278795372, -0.0745086308331193, -0.04004731939221323,
         0.015484875281325054, -0.18283988870179615, -0.015652160733754906],
        [0.0, 0.0, 0.0, -1.5708, 0.0, 1.5620463267948965, 0.0],
    ),
    ("panda", "joint"): (
        [0.5006081106448432, -0.33397569172122066, 0.10610615626755972, -0.22700286461369198,
         -0.12366028710753972, -0.07010112591260578, -0.7443198784491186],
        [0.00020046183423346752, -0.0004643442027347436, 0.00014447125888636438, -1.5709675363113602,
         -0.0002065459089026692, 1.8675419884821443, 5.743802683948732e-05],
    ),
}  # fmt: skip


@pytest.mark.parametrize(("name", "kind"), list(EXCITATIONS))
def test_random_fourier_draws_the_recorded_motions(name, kind):
    from dynid.sim.cases import case_excitation
    from dynid.sim.synthetic import random_fourier
    from dynid.symbolic import load_robot

    robot = load_robot(name)
    if kind == "case":
        traj = case_excitation(robot, 11, base_freq=0.5)
    else:
        traj = random_fourier(robot, np.random.default_rng(3), periods=2)
    a0, c = EXCITATIONS[name, kind]
    np.testing.assert_allclose(traj.a[0], a0, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(traj.c, c, rtol=1e-12, atol=1e-15)
    q, dq, ddq = traj.evaluate(np.linspace(0.0, traj.duration, 2001))
    assert np.all(q >= robot.q_min) and np.all(q <= robot.q_max)
    # Within 60 % of the limits (checked on a grid: a peak between its points may pass by a little).
    assert np.all(np.abs(dq) <= 0.61 * robot.dq_max) and np.all(np.abs(ddq) <= 0.61 * robot.ddq_max)


def test_case_posture_is_data_and_other_robots_swing_about_mid_range(robot):
    from dynid.sim.cases import CASE_POSTURES, case_centre, case_excitation

    assert np.array_equal(case_centre(robot), CASE_POSTURES["ur5"])
    other = replace(robot, name="my_arm")  # the same arm under a name the table does not list
    assert case_centre(other) is None
    traj = case_excitation(other, 11, base_freq=0.5)
    assert np.array_equal(traj.c, 0.5 * (np.maximum(robot.q_min, -np.pi) + np.minimum(robot.q_max, np.pi)))


def test_random_fourier_rejects_bad_options(robot):
    from dynid.sim.synthetic import random_fourier

    rng = np.random.default_rng(0)
    with pytest.raises(UsageError, match="scaling"):
        random_fourier(robot, rng, scaling="both")
    with pytest.raises(UsageError, match="still joints"):
        random_fourier(robot, rng, scaling="arm", still=(2,))
    with pytest.raises(UsageError, match="6 angles"):
        random_fourier(robot, rng, centre=[0.0, 1.0])
