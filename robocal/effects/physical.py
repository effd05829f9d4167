"""Physical reading of a fitted effect over the data (stiffness, amplitude, half-width, lag, growth, drift) and
its physical range. A value outside the range is evidence (the effect is then "the best available description",
with what to check), never a reason to drop an effect that predicts held-out points."""
from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from robocal.kinematics.gravity import GravityModel, gravity_torques
from .bases import effect_regressor
from robocal.kinematics.models import Kinematics
from .library import ARCMIN, LibraryOptions
from .model import FittedEffect

CHECK = {
    "joint_compliance": "check the link masses, the payload and the gravity direction of the config (robot.mass_kg, "
                        "robot.link_masses_kg, robot.gravity_direction_base); structure along the reach (link bending, "
                        "base compliance) also looks like this",
    "payload_deflection": "check the logged payloads and their centre of gravity (tool.payload_cog_flange_mm)",
    "gear_cyclic": "a joint covering a small part of its range turns a ratio (scale) error, an encoder error or a "
                   "drift in measurement order into a large harmonic; measure the joint's whole range in random order",
    "backlash": "check the approach directions (rows in measurement order) and the brake/servo settings",
    "readback_lag": "check that the q columns are read-back joints and the rows are in measurement order",
    "thermal_drift": "check the timestamps and temperatures",
    "axis_coupling": "check the wrist's coupling ratios in the controller",
    "registration_drift": "check the tracker stand and re-measure reference nests during the run",
}


def _dq(fe: FittedEffect, kin: Kinematics, q: np.ndarray, meta: Mapping) -> np.ndarray | None:
    b = fe.choice.build(kin.n).basis(kin, q, meta)
    return None if b.dq is None else b.dq @ fe.values


def reading(fe: FittedEffect, kin: Kinematics, q_rad: np.ndarray, meta: Mapping, gravity: GravityModel,
            opt: LibraryOptions = LibraryOptions()) -> dict:
    """{"quantities": {...}, "outside": [text], "plausible": bool, "check": text} of a fitted effect over the
    poses ``q_rad`` (N, n) with their metadata."""
    q = np.atleast_2d(q_rad)
    name, v = fe.choice.name, np.asarray(fe.values, float)
    opts = dict(fe.choice.options)
    quantities, outside = {}, []
    if name in ("joint_compliance", "payload_deflection"):
        dq = _dq(fe, kin, q, meta)
        arm = gravity.link_masses_kg if name == "joint_compliance" else np.zeros(kin.n)
        pay = meta.get("payload_kg")
        tau = gravity_torques(kin, q, arm, np.zeros(len(q)) if pay is None else pay, gravity.payload_cog_flange_mm,
                              gravity.gravity_base)
        lo, hi = opt.stiffness_range_nm_per_rad
        for j in fe.choice.build(kin.n).joints:
            t = tau[:, j - 1] - tau[:, j - 1].mean()
            d = dq[:, j - 1] - dq[:, j - 1].mean()
            c = float(t @ d / max(float(t @ t), 1e-300))
            k = 1.0 / c if c != 0 else math.inf
            defl = float(np.ptp(dq[:, j - 1])) / ARCMIN
            quantities[f"J{j}"] = {"stiffness_nm_per_rad": k, "deflection_range_arcmin": defl}
            if k < 0:
                outside.append(f"J{j} stiffness {k:.3g} N*m/rad is negative (the arm would rise under its weight)")
            elif not lo <= k <= hi:
                outside.append(f"J{j} stiffness {k:.3g} N*m/rad outside {lo:.0e}-{hi:.0e}")
            if defl > opt.max_deflection_arcmin:
                outside.append(f"J{j} deflects {defl:.1f}' over the data (> {opt.max_deflection_arcmin:g}')")
        quantities["mass_model"] = gravity.source
    elif name == "gear_cyclic":
        hs = tuple(opts.get("harmonics", (1, 2)))
        amp = {f"h{h}": math.hypot(v[2 * i], v[2 * i + 1]) / ARCMIN * 60.0 for i, h in enumerate(hs)}
        span = math.degrees(float(np.ptp(q[:, opts["joint"] - 1])))
        quantities = {"amplitude_arcsec": amp, "joint_span_deg": span}
        outside += [f"{h} amplitude {a:.0f}\" > {opt.max_gear_arcsec:g}\"" for h, a in amp.items()
                    if a > opt.max_gear_arcsec]
    elif name == "backlash":
        hw = {f"J{j}": abs(b) / 2.0 / ARCMIN for j, b in zip(opts["joints"], v)}
        quantities = {"half_width_arcmin": hw}
        outside += [f"{j} half-width {h:.2f}' > {opt.max_backlash_arcmin:g}'" for j, h in hw.items()
                    if h > opt.max_backlash_arcmin]
    elif name == "readback_lag":
        lag = {f"J{n[3:]}" if not n.endswith("memory") else f"J{n[3:-7]} memory": -float(x)
               for n, x in zip(fe.param_names, v)}
        quantities = {"lag_deg_per_deg": lag}
        outside += [f"{j} lag {x:+.2e} deg/deg beyond +-{opt.max_lag:g}" for j, x in lag.items() if abs(x) > opt.max_lag]
    elif name == "thermal_drift":
        from .bases import warmup
        u = float(np.max(np.abs(warmup(meta, len(q), float(opts.get("tau_s", 2700.0))))))
        growth = abs(v[0]) * u
        zero = {f"J{j}": abs(x) * u / ARCMIN for j, x in zip(opts.get("joints", ()), v[1:])}
        quantities = {"length_growth": growth, "zero_drift_arcmin": zero}
        if growth > opt.max_growth:
            outside.append(f"length growth {growth:.2g} > {opt.max_growth:g}")
        outside += [f"{j} zero drift {z:.1f}' > {opt.max_zero_drift_arcmin:g}'" for j, z in zero.items()
                    if z > opt.max_zero_drift_arcmin]
    elif name == "axis_coupling":
        quantities = {"coupling": dict(zip(fe.param_names, (float(x) for x in v)))}
        outside += [f"{n} = {x:+.3g} beyond +-{opt.max_coupling:g}" for n, x in zip(fe.param_names, v)
                    if abs(x) > opt.max_coupling]
    elif name == "registration_drift":
        dp = effect_regressor(kin, q, meta, fe.choice.build(kin.n)) @ v
        tr = float(np.max(np.linalg.norm(dp - dp.mean(axis=0), axis=1)))
        rot = float(np.max(np.abs(v[3::6]) + np.abs(v[4::6]) + np.abs(v[5::6]))) if len(v) else 0.0
        quantities = {"max_displacement_mm": tr, "rotation_rad": rot, "clock": opts.get("clock")}
        if tr > opt.max_drift_mm:
            outside.append(f"moves the SMR by {tr:.2f} mm over the run (> {opt.max_drift_mm:g} mm)")
        if rot > opt.max_drift_rad:
            outside.append(f"rotation {rot:.2g} rad over the run (> {opt.max_drift_rad:g})")
    return {"quantities": quantities, "outside": outside, "plausible": not outside,
            "check": CHECK.get(name, "") if outside else ""}
