"""The closed-loop tracking of the simulator (dynid.sim.tracking) on the modified-DH fixture arm (RRPR).

``ControllerGains.design`` against its formulas; ``TrackingLoop.integrate`` against what its method
promises: the first tick's command is the nominal inverse dynamics, a perfect nominal model tracks with an
integration error that shrinks with the control period, a wrong one with an error that shrinks with the
bandwidth, the reported accelerations are the truth's forward dynamics of the reported torques, the
logged angles sit on the encoder's grid, and a flexible joint gets its spring's substeps and its static
deflection.  One-second runs at 1 kHz: the file runs in about a second.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest

from dynid.sim.sensors import NoiseModel
from dynid.sim.tracking import ControllerGains, TrackingLoop
from dynid.sim.truth import build_truth
from dynid.symbolic import load_robot
from tests.conftest import DATA

RATE = 1000.0


@pytest.fixture(scope="module")
def robot():
    return load_robot(DATA / "rrpr_mdh.toml")


def _command(robot, rate=RATE, seconds=1.0):
    """A smooth sine per joint about the middle of its range: (t, qd, dqd, ddqd)."""
    t = np.arange(round(seconds * rate) + 1) / rate
    c = 0.5 * (robot.q_min + robot.q_max)
    a = 0.2 * 0.5 * (robot.q_max - robot.q_min)
    w = 2 * np.pi * np.array([0.5, 0.7, 0.9, 1.1])
    arg = w * t[:, None]
    return t, c + a * np.sin(arg), a * w * np.cos(arg), -a * w**2 * np.sin(arg)


def _run(truth, *, bandwidth=10.0, noise=None, rate=RATE, substeps=None):
    loop = TrackingLoop(
        truth, ControllerGains.design(truth.nominal.n, bandwidth=bandwidth), noise or NoiseModel.off(), rate, substeps
    )
    t, qd, dqd, ddqd = _command(truth.nominal, rate)
    return loop, qd, loop.integrate(t, qd, dqd, ddqd)


def test_design_sets_the_gains_of_a_second_order_loop():
    g = ControllerGains.design(3, bandwidth=8.0, damping=0.5)
    w = 2 * math.pi * 8.0
    np.testing.assert_allclose(g.kp, w * w)
    np.testing.assert_allclose(g.kd, 2 * 0.5 * w)
    assert g.kp.shape == g.kd.shape == (3,) and g.bandwidth == 8.0 and g.damping == 0.5
    # the closed loop e'' + kd e' + kp e = 0 has its poles at the design's frequency and damping
    poles = np.roots([1.0, g.kd[0], g.kp[0]])
    assert np.abs(poles[0]) == pytest.approx(w) and -poles[0].real / w == pytest.approx(0.5)
    d = g.to_dict()
    assert d["kp"] == g.kp.tolist() and d["bandwidth_hz"] == 8.0 and d["velocity_cutoff_hz"] == 100.0


def test_the_first_command_is_the_nominal_inverse_dynamics(robot):
    truth = build_truth(robot, friction="none", perturb=0.2, truth_seed=3)
    _, qd, out = _run(truth)
    _, qd, dqd, ddqd = _command(robot)
    model = robot.pin_model
    expected = pin.rnea(model, model.createData(), qd[0], dqd[0], ddqd[0])
    # the loop starts on the command: no tracking error, the feedforward alone
    np.testing.assert_allclose(out["tau_drive"][0], expected, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(out["q"][0], qd[0])
    assert set(out) >= {"q", "dq", "ddq", "theta", "dtheta", "ddtheta", "q_meas", "tau_drive", "components"}
    assert all(out[k].shape == qd.shape for k in ("q", "dq", "ddq", "q_meas", "tau_drive"))


def test_a_perfect_model_tracks_to_the_integration_error(robot):
    """Truth = nominal, no friction.  With the velocity filter out of the way (a cut-off far above the
    rate), what is left is the integration's and the backward difference's error: first order in the
    control period.  With the default 100 Hz filter, its lag dominates and does not shrink with the rate."""
    truth = build_truth(robot, friction="none")

    def error(rate, cutoff):
        gains = replace(ControllerGains.design(robot.n), velocity_cutoff=cutoff)
        t, qd, dqd, ddqd = _command(robot, rate)
        out = TrackingLoop(truth, gains, NoiseModel.off(), rate, None).integrate(t, qd, dqd, ddqd)
        return np.abs(out["q"] - qd).max()

    fast = [error(rate, 1e6) for rate in (500.0, 2000.0)]
    assert fast[0] < 1e-3
    assert fast[0] / fast[1] == pytest.approx(4.0, rel=0.1)  # four times the rate: four times smaller
    lagged = [error(rate, 100.0) for rate in (500.0, 2000.0)]
    assert lagged[1] > 3 * fast[1] and lagged[0] / lagged[1] < 1.5


def test_a_wrong_model_is_tracked_more_closely_at_a_higher_bandwidth(robot):
    truth = build_truth(robot, friction="none", perturb=0.3, truth_seed=1)
    err = {}
    for bw in (4.0, 16.0):
        _, qd, out = _run(truth, bandwidth=bw)
        err[bw] = np.abs(out["q"] - qd).max()
    assert err[4.0] > 1e-3  # the model error shows at a low bandwidth
    assert err[16.0] < 0.2 * err[4.0]  # the PD rejects it as 1 / bandwidth^2 (16 times less)


def test_the_reported_states_are_the_truth_s_forward_dynamics_with_its_friction(robot):
    truth = build_truth(robot, friction="linear", perturb=0.1, truth_seed=2)
    assert truth.friction.active
    loop, _, out = _run(truth)
    assert loop.substeps == 2  # rigid: the default minimum
    fric = out["components"]["friction"]
    model = truth.robot.pin_model
    data = model.createData()
    for k in (0, 137, 600, 1000):
        f, _ = truth.friction.torque(out["dq"][k])
        np.testing.assert_allclose(fric[k], f, rtol=1e-12, atol=1e-12)
        ddq = pin.aba(model, data, out["q"][k], out["dq"][k], out["tau_drive"][k] - fric[k])
        np.testing.assert_allclose(out["ddq"][k], ddq, rtol=1e-9, atol=1e-9)
    assert np.abs(fric).max() > 0.1  # the friction acts
    # rigid joints: the drive side is the link side
    np.testing.assert_array_equal(out["theta"], out["q"])
    np.testing.assert_array_equal(out["q_meas"], out["q"])  # exact encoders


def test_the_logged_angles_sit_on_the_encoder_grid(robot):
    truth = build_truth(robot, friction="none")
    bits = 12
    noise = NoiseModel(torque=0.0, coloured=0.0, colour=0.0, encoder_bits=bits, current_lsb=0.0, control_bits=0)
    _, _, out = _run(truth, noise=noise)
    step = 2 * math.pi / 2**bits
    counts = out["q_meas"] / step
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)
    assert np.abs(out["q_meas"] - out["q"]).max() <= 0.5 * step + 1e-12
    assert np.abs(out["q_meas"] - out["q"]).max() > 0.1 * step  # they are quantised


def test_a_stiff_spring_gets_its_substeps_and_starts_at_its_static_deflection(robot):
    truth = build_truth(robot, friction="none", effects="elasticity@2")
    tr = truth.transmission
    assert tr is not None and tr.joints.tolist() == [1]
    stiff = replace(truth, transmission=replace(tr, stiffness=100 * tr.stiffness))
    T = stiff.transmission
    omega = np.sqrt(T.stiffness * (1 / T.motor_inertia + 1 / stiff.scales.inertia[T.joints]))
    loop, qd, out = _run(stiff)
    assert loop.substeps == max(2, math.ceil(float(omega.max()) / RATE / 0.3)) > 2
    assert _run(stiff, substeps=5)[0].substeps == 5  # given: kept
    # the motor side is ahead of the link by the spring's deflection under the link's torque
    link = stiff.link_robot.pin_model
    _, qd, dqd, ddqd = _command(robot)
    tau_s = pin.rnea(link, link.createData(), qd[0], dqd[0], ddqd[0])[1]
    assert out["theta"][0, 1] - out["q"][0, 1] == pytest.approx(tau_s / T.stiffness[0], rel=1e-9)
    rigid = [0, 2, 3]
    np.testing.assert_array_equal(out["theta"][:, rigid], out["q"][:, rigid])
    # the controller reads the motor side: the link still follows the command
    assert np.abs(out["q"] - qd).max() < 0.02
