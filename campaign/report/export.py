"""Export a calibrated model for other tools: URDF, a DH table as CSV, and a RoboDK-style DH(M) table.

URDF (metres, radians): each revolute joint ``jK`` rotates about its own z axis by the controller's joint value
q_K; its ``origin`` holds the fixed part of the chain between joint K-1 and joint K, so the URDF reproduces the
project's forward kinematics exactly for standard DH, modified DH and Hayati's beta:

* ``dh``  ``T_i = Rz(q_i) S_i`` with ``S_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i) Ry(beta_i)``:
  origin of joint 1 = identity, of joint K = ``S_{K-1}``, fixed joint ``flange`` = ``S_n``;
* ``mdh`` ``T_i = A_i Rz(q_i) B_i`` with ``A_i = Rx(alpha_i) Ry(beta_i) Tx(a_i) Rz(theta_i)``, ``B_i = Tz(d_i)``:
  origin of joint K = ``B_{K-1} A_K``, fixed joint ``flange`` = ``B_n``.

The tool (the SMR centre, ``p_flange_smr_mm``) is a fixed link ``tool`` on the flange. The registration
``T_tracker_base`` and any residual layer (IDW/GPR: not a kinematic chain) are stated in comments, and so is every
identified parameter with its std (the model's record, ``CalibratedModel.parameters``: the same numbers as
report.json ``parameters``); the DH CSV and the RoboDK table carry the std beside each value.

Joint limits (:class:`UrdfLimits`, from the config): position limits from ``robot.joints[].q_min_deg/q_max_deg``,
velocity from ``robot.max_joint_speed_deg_s`` (rad/s, every joint), effort from the datasheet torques when given,
else omitted (never ``0``: ROS tools take a zero limit literally).
"""
from __future__ import annotations

from dataclasses import dataclass
import warnings
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np
from scipy.spatial.transform import Rotation

from robocal.kinematics.models import JOINT_PARAMS, Kinematics
from robocal.layers.calibrated_model import CalibratedModel

from campaign.config.schema import CampaignConfig
from campaign.errors import DataError
from campaign.io.csv_cells import render_rows
from campaign.io.durable import atomic_write


@dataclass(frozen=True)
class UrdfLimits:
    """Per joint (n,): position limits (rad), velocity limit (rad/s) and effort limit (N*m, None: omitted)."""
    q_min_rad: tuple[float, ...]
    q_max_rad: tuple[float, ...]
    velocity_rad_s: tuple[float, ...]
    effort_nm: tuple[float, ...] | None = None
    source: str = "config"

    @classmethod
    def of_config(cls, cfg: CampaignConfig, effort_nm: tuple[float, ...] | None = None) -> "UrdfLimits":
        """The config's joint limits and ``robot.max_joint_speed_deg_s`` for every joint; ``effort_nm``: datasheet
        torques, one value for every joint or one per joint (DataError otherwise)."""
        joints = cfg.robot.joints
        n = len(joints)
        if effort_nm is not None:
            if len(effort_nm) not in (1, n) or min(effort_nm) <= 0:
                raise DataError("--effort-nm", f"expected one positive torque (N*m) or {n}, got {len(effort_nm)}")
            effort_nm = tuple(float(e) for e in effort_nm) * (n if len(effort_nm) == 1 else 1)
        speed = float(np.radians(cfg.robot.max_joint_speed_deg_s))
        si = lambda j, v: v / 1000.0 if j.type == "prismatic" else float(np.radians(v))   # noqa: E731  (m, rad)
        return cls(tuple(si(j, j.q_min_deg) for j in joints), tuple(si(j, j.q_max_deg) for j in joints),
                   tuple(cfg.robot.max_tcp_speed_mm_s / 1000.0 if j.type == "prismatic" else speed for j in joints),
                   effort_nm,
                   f"config {cfg.name}: robot.joints limits, robot.max_joint_speed_deg_s "
                   f"{cfg.robot.max_joint_speed_deg_s:g} deg/s")


def _limit_xml(limits: UrdfLimits, i: int) -> str:
    """``<limit>`` of joint ``i`` at full precision; no effort attribute without datasheet torques."""
    f = lambda v: repr(float(v))  # noqa: E731
    effort = "" if limits.effort_nm is None else f' effort="{f(limits.effort_nm[i])}"'
    return (f'<limit lower="{f(limits.q_min_rad[i])}" upper="{f(limits.q_max_rad[i])}"'
            f' velocity="{f(limits.velocity_rad_s[i])}"{effort}/>')


def _rot(axis: str, angle_rad: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler(axis, angle_rad).as_matrix()
    return T


def _trans(axis: str, length_mm: float) -> np.ndarray:
    T = np.eye(4)
    T["xyz".index(axis), 3] = length_mm
    return T


def joint_origins(kin: Kinematics) -> tuple[list[np.ndarray], np.ndarray]:
    """Fixed transforms (4, 4) mm: the origin of each joint (n of them) and of the flange, such that
    ``T_base_flange(q) = O_1 Rz(q_1) O_2 Rz(q_2) ... O_n Rz(q_n) O_flange``."""
    n, t = kin.n, kin.n_track                  # a track's row is unused: the carriage only translates
    if kin.convention == "dh":
        S = [np.eye(4) if i < t else _rot("z", kin.theta_rad[i]) @ _trans("z", kin.d_mm[i]) @ _trans("x", kin.a_mm[i])
             @ _rot("x", kin.alpha_rad[i]) @ _rot("y", kin.beta_rad[i]) for i in range(n)]
        return [np.eye(4)] + S[:-1], S[-1]
    A = [np.eye(4) if i < t else _rot("x", kin.alpha_rad[i]) @ _rot("y", kin.beta_rad[i]) @ _trans("x", kin.a_mm[i])
         @ _rot("z", kin.theta_rad[i]) for i in range(n)]
    B = [np.eye(4) if i < t else _trans("z", kin.d_mm[i]) for i in range(n)]
    return [A[0]] + [B[i - 1] @ A[i] for i in range(1, n)], B[-1]


def _origin_xml(T_mm: np.ndarray) -> str:
    xyz = T_mm[:3, 3] / 1000.0
    with warnings.catch_warnings():     # at pitch +-90 deg scipy sets yaw to 0 and says so; the angles it returns
        warnings.simplefilter("ignore", UserWarning)    # still give this rotation (the URDF test checks the chain)
        rpy = Rotation.from_matrix(T_mm[:3, :3]).as_euler("xyz")      # extrinsic x-y-z = URDF roll, pitch, yaw
    fmt = lambda v: " ".join(repr(float(x)) for x in v)  # noqa: E731  (full precision)
    return f'<origin xyz="{fmt(xyz)}" rpy="{fmt(rpy)}"/>'


def _track_axis_xyz(kin: Kinematics) -> str:
    """The track's unit direction (base frame) for a URDF prismatic joint (its length, the scale, is in a comment)."""
    u = kin.track / np.linalg.norm(kin.track)
    return " ".join(repr(float(v)) for v in u)


def urdf_text(model: CalibratedModel, limits: UrdfLimits, name: str = "robot") -> str:
    """The URDF document (links base_link, link1..linkN, flange, tool) of the model's kinematic layer, with the
    joint ``limits``."""
    kin = model.kinematics
    if len(limits.q_min_rad) != kin.n:
        raise DataError("export", f"the model has {kin.n} joints but the limits {len(limits.q_min_rad)}")
    origins, O_flange = joint_origins(kin)
    T = np.asarray(kin.T_tracker_base)
    notes = [f"calibrated kinematic chain exported by robot-accuracy-campaign ({kin.convention.upper()}"
             f"{' + Hayati beta on joints ' + ','.join(str(i + 1) for i, h in enumerate(kin.hayati) if h) if any(kin.hayati) else ''})",
             "units: metres and radians; joint values are the controller's (the DH theta offsets are in the origins)",
             "tool link = SMR centre p_flange_smr_mm = " + ", ".join(f"{v:.4f}" for v in kin.p_flange_smr_mm) + " mm",
             "registration T_tracker_base (mm) rows: " + "; ".join(" ".join(f"{v:.6f}" for v in row) for row in T),
             f"joint limits from {limits.source}; velocity in rad/s, "
             + ("effort in N*m (datasheet)" if limits.effort_nm is not None else
                "effort omitted (no datasheet torque given: add effort=\"N*m\" where a tool requires it, e.g. "
                "urdfdom)")]
    if kin.track is not None:
        notes.append(f"j1 is the linear track (prismatic, metres); the carriage travels "
                     f"{np.linalg.norm(kin.track):.9f} x the controller's position (identified scale): command "
                     "j1 = that product")
    if getattr(model, "effects", ()):
        names = ", ".join(getattr(fe.choice, "label", type(fe).__name__) for fe in model.effects)
        notes.append(f"NOT exported: the physical effects of the model ({names}: joint-angle dependent, not a fixed "
                     "chain); this URDF is its geometric part only")
    if model.residual is not None:
        kind = type(model.residual).__name__
        notes.append(f"NOT exported: the non-kinematic residual layer ({kind}) of the model corrects positions "
                     "beyond this chain; use model.json with campaign correct for the full accuracy")
    notes += parameter_notes(model)
    lines = ['<?xml version="1.0"?>'] + [f"<!-- {n.replace('--', '-')} -->" for n in notes]
    lines.append(f"<robot name={quoteattr(name)}>")
    links = ["base_link"] + [f"link{i + 1}" for i in range(kin.n)] + ["flange", "tool"]
    lines += [f'  <link name="{ln}"/>' for ln in links]
    for i in range(kin.n):
        kind, axis = ("prismatic", _track_axis_xyz(kin)) if i < kin.n_track else ("revolute", "0 0 1")
        lines += [f'  <joint name="j{i + 1}" type="{kind}">', f'    <parent link="{links[i]}"/>',
                  f'    <child link="{links[i + 1]}"/>', f"    {_origin_xml(origins[i])}", f'    <axis xyz="{axis}"/>',
                  f"    {_limit_xml(limits, i)}", "  </joint>"]
    tool = np.eye(4)
    tool[:3, 3] = kin.p_flange_smr_mm
    for jname, parent, child, Tj in (("flange_joint", links[kin.n], "flange", O_flange),
                                     ("tool_joint", "flange", "tool", tool)):
        lines += [f'  <joint name="{jname}" type="fixed">', f'    <parent link="{parent}"/>',
                  f'    <child link="{child}"/>', f"    {_origin_xml(Tj)}", "  </joint>"]
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


def parameter_std(model: CalibratedModel, name: str) -> float | None:
    """The std of parameter ``name`` in the model's record (``CalibratedModel.parameters``) in the unit the exports
    print (deg for angles, mm); None when it was not identified or the model has no record (an earlier version)."""
    row = None if model.parameters is None else model.parameters.row(name)
    if row is None or row.std is None:
        return None
    return float(np.degrees(row.std)) if row.unit == "rad" else float(row.std)


def _std_text(model: CalibratedModel, name: str | None) -> str:
    """``parameter_std`` as the RoboDK table prints it ("-": no parameter, or not identified)."""
    v = None if name is None else parameter_std(model, name)
    return "-" if v is None else f"{v:.6g}"


def parameter_notes(model: CalibratedModel) -> list[str]:
    """One line per identified parameter of the model's record: value (deg / mm; base entries have none: the base
    is T_tracker_base), delta from nominal and std: the URDF's comments, where the format has no place for them."""
    table = model.parameters
    if table is None:
        return ["parameter std: not recorded (a model.json of an earlier version)"]
    out = [f"identified parameters of model.json (value, delta from nominal, base relative to the registered frame; "
           f"std from the {table.fit} fit; deg and mm)"]
    for row in (r.to_dict() for r in table.rows if r.identified):
        value = "-" if row["value"] is None else f"{row['value']:.6f}"
        sd = "-" if row["std"] is None else f"{row['std']:.6g}"
        out.append(f"parameter {row['name']} {value} {row['unit']} delta {row['delta']:+.6f} std {sd}")
    return out


def dh_rows(kin: Kinematics) -> list[dict]:
    """One row per joint: theta offset, d, a, alpha, beta (deg / mm) and joint limits (deg)."""
    return [{"joint": i + 1, "convention": kin.convention, "theta_deg": float(np.degrees(kin.theta_rad[i])),
             "d_mm": float(kin.d_mm[i]), "a_mm": float(kin.a_mm[i]), "alpha_deg": float(np.degrees(kin.alpha_rad[i])),
             "beta_deg": float(np.degrees(kin.beta_rad[i])), "q_min_deg": float(np.degrees(kin.q_min_rad[i])),
             "q_max_deg": float(np.degrees(kin.q_max_rad[i]))} for i in range(kin.n)]


DH_STD_COLUMNS = ("theta_std_deg", "d_std_mm", "a_std_mm", "alpha_std_deg", "beta_std_deg")


def write_dh_csv(model: CalibratedModel, path: str | Path) -> Path:
    """CSV of the calibrated table (``dh_rows``) plus a ``tool`` row (SMR centre in the flange frame, mm), then the
    std of each value (``DH_STD_COLUMNS``, from the model's record; empty where not identified; the tool row's
    std of x, y, z in the first three)."""
    rows = dh_rows(model.kinematics)
    p = model.kinematics.p_flange_smr_mm
    cell = lambda v: "" if v is None else f"{v:.9g}"  # noqa: E731
    table = [[r["joint"], r["convention"]] + [f"{r[k]:.9g}" for k in list(r)[2:]]
             + [cell(parameter_std(model, f"{kind}{r['joint']}")) for kind in JOINT_PARAMS] for r in rows]
    table.append(["tool", "p_flange_smr_mm", f"{p[0]:.9g}", f"{p[1]:.9g}", f"{p[2]:.9g}", "", "", "", ""]
                 + [cell(parameter_std(model, f"tool_{a}")) for a in "xyz"] + ["", ""])
    track = model.kinematics.track
    if track is not None:           # joint 1's row: travel limits in mm; its displacement per mm of travel here
        table[0][1] = "prismatic"
        table.append(["track", "displacement_per_mm", f"{track[0]:.9g}", f"{track[1]:.9g}", f"{track[2]:.9g}", "", "",
                      "", ""] + [cell(parameter_std(model, f"track_{a}")) for a in "xyz"] + ["", ""])
    return atomic_write(path, render_rows(list(rows[0]) + list(DH_STD_COLUMNS), table,
                                          text_columns=(0, 1)).encode("utf-8"))


def dhm_from_dh(kin: Kinematics) -> tuple[list[tuple[float, float, float, float]], tuple[float, float]]:
    """Exact modified-DH (Craig) rows (alpha_deg, a_mm, theta_deg, d_mm) of a standard-DH chain without beta,
    and the flange transform Tx(a_n) Rx(alpha_n) left over as (a_mm, alpha_deg): Tx(a) Rx(alpha) of joint i
    moves to the front of joint i + 1 (they commute)."""
    al, a = np.degrees(kin.alpha_rad), kin.a_mm
    rows = [((0.0 if i == 0 else float(al[i - 1])), (0.0 if i == 0 else float(a[i - 1])),
             float(np.degrees(kin.theta_rad[i])), float(kin.d_mm[i])) for i in range(kin.n)]
    return rows, (float(a[-1]), float(al[-1]))


def _robodk_header(cols: tuple[str, ...]) -> str:
    return f"{'joint':>5} " + " ".join(f"{c:>14}" for c in cols) + " " + " ".join(f"{'std_' + c:>18}" for c in cols)


def robodk_text(model: CalibratedModel) -> str:
    """The calibrated table as RoboDK users type it by hand (DHM columns alpha, a, theta, d; mm and deg), each value's
    std beside it (from the model's record; ``-``: not identified). A robot on a track is refused (DataError): the
    table has no prismatic joint."""
    kin = model.kinematics
    if kin.track is not None:
        raise DataError("--robodk", "the robot is on a linear track: RoboDK's DH(M) robot table has no prismatic "
                                    "joint (use --urdf or --dh-csv, which carry the track)")
    p = kin.p_flange_smr_mm
    std = lambda name: _std_text(model, name)  # noqa: E731
    out = ["# Calibrated kinematics for manual entry (robot panel, DHM table). mm and deg.",
           "# theta is the offset added to the controller's joint value; std_*: the value's standard deviation "
           f"({'std from the ' + model.parameters.fit + ' fit' if model.parameters else 'not recorded'}; "
           "- = not identified, kept at nominal)."]
    if kin.convention == "dh" and not np.any(kin.beta_rad):
        rows, (a_f, al_f) = dhm_from_dh(kin)
        out.append("# converted exactly from the standard-DH model: DHM row i takes alpha, a of DH joint i-1")
        cols = ("alpha_deg", "a_mm", "theta_deg", "d_mm")
        out.append(_robodk_header(cols))
        for i, r in enumerate(rows):
            names = (None, None) if i == 0 else (f"alpha{i}", f"a{i}")
            names += (f"theta{i + 1}", f"d{i + 1}")
            out.append(f"{i + 1:>5} " + " ".join(f"{v:>14.6f}" for v in r) + " "
                       + " ".join(f"{std(n):>18}" for n in names))
        n = kin.n
        out.append(f"# flange: then Tx({a_f:.6f} mm) Rx({al_f:.6f} deg) before the tool (std_a_mm {std(f'a{n}')}, "
                   f"std_alpha_deg {std(f'alpha{n}')})")
    else:
        label = "DHM (modified, Craig)" if kin.convention == "mdh" else "standard DH (Hayati beta: no exact DHM form)"
        out.append(f"# convention: {label}; beta = Hayati rotation about y (RoboDK calibration: 'beta' column)")
        cols = ("alpha_deg", "a_mm", "theta_deg", "d_mm", "beta_deg")
        out.append(_robodk_header(cols))
        for r in dh_rows(kin):
            j = r["joint"]
            out.append(f"{j:>5} " + " ".join(f"{r[c]:>14.6f}" for c in cols) + " "
                       + " ".join(f"{std(c.split('_')[0] + str(j)):>18}" for c in cols))
    out.append(f"# tool (TCP = SMR centre, flange frame): X {p[0]:.6f}  Y {p[1]:.6f}  Z {p[2]:.6f} mm (std_X "
               f"{std('tool_x')}, std_Y {std('tool_y')}, std_Z {std('tool_z')})")
    if model.residual is not None or getattr(model, "effects", ()):
        out.append("# not representable here: the model's physical effects / residual layer (use model.json with "
                   "campaign correct)")
    return "\n".join(out) + "\n"


def export_model(model: CalibratedModel, urdf: Path | None = None, dh_csv: Path | None = None,
                 robodk: Path | None = None, name: str = "robot", limits: UrdfLimits | None = None) -> list[Path]:
    """Write the requested files (the URDF needs ``limits``); returns their paths."""
    written = []
    if urdf:
        if limits is None:
            raise DataError("--urdf", "the URDF's joint limits come from the config: give --config CONFIG (the model is not in a "
                                     "run directory with its config.yaml)")
        atomic_write(Path(urdf), urdf_text(model, limits, name).encode())
        written.append(Path(urdf))
    if dh_csv:
        written.append(write_dh_csv(model, dh_csv))
    if robodk:
        atomic_write(Path(robodk), robodk_text(model).encode())
        written.append(Path(robodk))
    return written
