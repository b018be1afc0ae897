"""What an export loses, measured on held-out data: the share of each part a simulator cannot carry.

The identified model's prediction of a dataset is split (each part filtered like the torque, as
:meth:`IdentifiedModel.predict_parts` does) into

* the rigid body + armature of the identified parameters,
* the friction of the model (layer-1 linear friction and / or the layer-2 friction model),
* the mixture correction (layer 3),
* each effect term,

and the exported description's prediction into its rigid body (consistent standard parameters, with
the armature for MJCF, without it for URDF) and its ``frictionloss * sign(dq) + damping * dq``.  For
each part the exported description changes or leaves out, :func:`heldout_shares` reports the held-out
RMS of dynid's full model without that difference (``rms_without``) against the full model's
(``rms_full``); and the RMS of the exported description itself (``rms_exported``).  The parts interact,
so the rises do not add up to the total; each is the part alone.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynid.data.dataset import Dataset
from dynid.identify.columns import column_set, linear_torque

__all__ = ["heldout_shares"]


def _rms(r: NDArray[np.float64]) -> list[float]:
    return [float(v) for v in np.sqrt(np.mean(r**2, axis=0))]


def heldout_shares(model, params, fmt: str, data: Dataset) -> dict[str, Any]:
    """Held-out RMS of dynid's model, of the exported description, and of the model without each lost part.

    Parameters
    ----------
    model : IdentifiedModel
        The identified model.
    params : SimParameters
        What the export writes.
    fmt : {"urdf", "mjcf"}
        Format (URDF carries no armature).
    data : Dataset
        Held-out data of the same robot.

    Returns
    -------
    dict
        ``rms_full``, ``rms_exported`` (per joint, N m), ``parts`` (list of ``{"part", "rms_without",
        "rise_mean"}``), ``closure`` (largest absolute difference, N m, between the full prediction and
        the sum of its parts; ~0).
    """
    robot = model.robot
    n = robot.n
    cols = model.columns
    prep = model.prepare(data)
    rows = prep.rows
    ref = prep.tau_reference
    parts = model.predict_parts(data, prep=prep)
    full = parts["link"] + parts["friction"] + parts["gmm"]

    def filt(tau):
        return prep.filter(tau)[rows]

    kinds = np.array(cols.kinds)
    rigid = filt(linear_torque(cols, model.params, prep.q, prep.dq, prep.ddq, mask=np.isin(kinds, ("link", "armature"))))
    in_link = np.isin(kinds, ("coulomb", "viscous", "offset")) & (
        cols.coupled_mask | (model.friction_source == "layer1")
    )
    friction = parts["friction"]
    if in_link.any():
        friction = friction + filt(linear_torque(cols, model.params, prep.q, prep.dq, prep.ddq, mask=in_link))
    effects: list[tuple[str, NDArray[np.float64]]] = []
    if cols.n_effect:
        values = model.effect_columns(prep.q, prep.dq, prep.ddq, t=prep.t, runs=prep.runs, fs=prep.fs)
        eff_idx = np.flatnonzero(cols.effect_mask)
        for i, term in enumerate(cols.effects):
            mask = np.zeros(cols.p, dtype=bool)
            mask[eff_idx[cols.effect_owner == i]] = True
            effects.append(
                (
                    f"effect term {term.key}",
                    filt(linear_torque(cols, model.params, prep.q, prep.dq, prep.ddq, mask=mask, effect_values=values)),
                )
            )
    closure = float(np.abs(full - rigid - friction - parts["gmm"] - sum(e for _, e in effects)).max(initial=0.0))

    plain = column_set(robot.with_transmission(None), friction=True, armature=True)
    armature = params.armature if fmt == "mjcf" else np.zeros(n)
    zeros = np.zeros(n)
    x_rigid = plain.P @ np.concatenate([params.standard, armature, zeros, zeros, zeros])
    x_fric = plain.P @ np.concatenate([np.zeros(10 * n), zeros, params.frictionloss, params.damping, zeros])
    exp_rigid = filt(linear_torque(plain, x_rigid, prep.q, prep.dq, prep.ddq))
    exp_fric = filt(linear_torque(plain, x_fric, prep.q, prep.dq, prep.ddq))
    exported = exp_rigid + exp_fric

    base = _rms(ref - full)
    lost = [
        (
            "rigid body: consistency projection"
            + (", armature (no URDF field)" if fmt == "urdf" else "")
            + (", coupled-motor cross terms" if robot.transmission is not None else ""),
            rigid - exp_rigid,
        ),
        ("friction beyond Coulomb + viscous (offset, Stribeck, asymmetry, nonlinear)", friction - exp_fric),
        ("GMM correction", parts["gmm"]),
        *effects,
    ]
    out_parts = []
    scale = float(np.abs(full).max(initial=0.0))
    for name, tau in lost:
        if not np.abs(tau).max(initial=0.0) > 1e-12 * scale:  # nothing lost (rounding only)
            continue
        without = _rms(ref - full + tau)
        out_parts.append(
            {
                "part": name,
                "rms_without": without,
                "rise_mean": float(np.mean(without) - np.mean(base)),
            }
        )
    return {
        "data": str(data.meta.get("source", "")) if hasattr(data, "meta") and data.meta else "",
        "rms_full": base,
        "rms_exported": _rms(ref - exported),
        "rms_full_mean": float(np.mean(base)),
        "rms_exported_mean": float(np.mean(_rms(ref - exported))),
        "parts": out_parts,
        "closure": closure,
    }
