"""Write-back formats and safety bounds (campaign.correct)."""
from __future__ import annotations

import csv
import dataclasses
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from campaign.correct import bounds
from campaign.correct import rapid_module
from campaign.correct import ur_program
from campaign.correct import target_csv
from drivers.rapid import literals
from drivers import rapid
from campaign.correct.bounds import CorrectedTarget, Rejected

pytestmark = pytest.mark.unit

Q_MIN = (-180.0, -95.0, -180.0, -400.0, -120.0, -400.0)
Q_MAX = (180.0, 155.0, 75.0, 400.0, 120.0, 400.0)
LIMITS = dict(q_min_deg=Q_MIN, q_max_deg=Q_MAX)
TRICKY_IDS = ('quote"d', "back\\slash", "caf\u00e9", "comma,id", "x" * 80)


def make_targets(n: int = 12, seed: int = 1, ids=None) -> list[CorrectedTarget]:
    """n valid targets within the limits, random but seeded."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        q_nom = rng.uniform(np.array(Q_MIN) + 5, np.array(Q_MAX) - 5)
        q_cor = q_nom + rng.uniform(-0.2, 0.2, 6)
        quat = rng.normal(size=4)
        quat /= np.linalg.norm(quat)
        conf = tuple(int(c) for c in rng.integers(-2, 3, 3)) + (int(rng.integers(0, 8)),)
        rot = math.nan if k % 3 == 0 else float(rng.uniform(0, 0.05))
        tid = ids[k] if ids else f"P{k + 1:03d}"
        out.append(CorrectedTarget(tid, tuple(map(float, q_nom)), tuple(map(float, q_cor)),
                                   tuple(map(float, rng.uniform(-2500, 2500, 3))), tuple(map(float, quat)),
                                   conf, solver_tolerance_mm=float(rng.uniform(0, 1e-4)),
                                   predicted_error_mm=float(rng.uniform(0.02, 0.3)), predicted_rot_err_deg=rot,
                                   predicted_std_mm=float(rng.uniform(0.001, 0.05))))
    return out


def check(targets, **kw):
    kw.setdefault("max_joint_correction_deg", 1.0)
    return bounds.check_targets(targets, Q_MIN, Q_MAX, **kw)


def write_all(tmp_path: Path, targets, tag: str = "") -> dict[str, Path]:
    """Every target writer run on ``targets``; name -> path."""
    paths = {name: tmp_path / f"{name}{tag}.{ext}" for name, ext in
             (("rapid", "mod"), ("ur_json", "json"), ("urscript", "script"), ("csv", "csv"))}
    rapid_module.write_rapid_module(paths["rapid"], targets, **LIMITS)
    ur_program.write_ur_json(paths["ur_json"], targets, **LIMITS)
    ur_program.write_urscript(paths["urscript"], targets, **LIMITS)
    target_csv.write_targets_csv(paths["csv"], targets, **LIMITS)
    return paths


# --------------------------------------------------------------------------
# bounds


def test_valid_targets_are_all_accepted_in_order():
    targets = make_targets()
    accepted, rejected = check(targets)
    assert accepted == targets and rejected == []


def test_joint_limit_rejection_names_joint_and_values():
    t = make_targets(1)[0]
    q = list(t.q_corrected_deg)
    q[1] = 155.25
    bad = dataclasses.replace(t, q_corrected_deg=tuple(q), q_nominal_deg=tuple(q))
    accepted, rejected = check([bad])
    assert accepted == [] and len(rejected) == 1
    reason = rejected[0].reason
    assert rejected[0].target_id == "P001"
    assert "j2" in reason and "155.25" in reason and "-95" in reason and "155" in reason
    assert "\n" not in reason


def test_correction_bound_rejection():
    t = make_targets(1)[0]
    q = list(t.q_nominal_deg)
    q[2] += 1.5
    bad = dataclasses.replace(t, q_corrected_deg=tuple(q))
    _, rejected = check([bad], max_joint_correction_deg=1.0)
    assert "j3" in rejected[0].reason and "1.5" in rejected[0].reason and "exceeds 1 deg" in rejected[0].reason
    accepted, _ = check([bad], max_joint_correction_deg=2.0)
    assert accepted == [bad]


def test_position_bound_rejection():
    t1, t2 = make_targets(2)
    p_target = {t1.target_id: tuple(np.add(t1.p_command_base_mm, (3.0, 0.0, 4.0))),   # 5 mm away
                t2.target_id: tuple(np.add(t2.p_command_base_mm, (0.0, 0.5, 0.0)))}   # 0.5 mm away
    accepted, rejected = check([t1, t2], max_position_correction_mm=2.0, p_target_base_mm=p_target)
    assert accepted == [t2]
    assert "moved 5" in rejected[0].reason and "bound 2 mm" in rejected[0].reason
    _, rejected = check([t1, t2], max_position_correction_mm=2.0, p_target_base_mm={t2.target_id: p_target[t2.target_id]})
    assert [r.target_id for r in rejected] == [t1.target_id] and "no target position" in rejected[0].reason


@pytest.mark.parametrize("field, value, words", [
    ("q_corrected_deg", (0.0, math.nan, 0.0, 0.0, 0.0, 0.0), ["non-finite", "q_corrected_deg[1]"]),
    ("q_nominal_deg", (0.0, 0.0, math.inf, 0.0, 0.0, 0.0), ["non-finite", "q_nominal_deg[2]"]),
    ("p_command_base_mm", (1.0, math.nan, 2.0), ["non-finite", "p_command_base_mm[1]"]),
    ("quat_command_wxyz", (math.nan, 0.0, 0.0, 1.0), ["non-finite", "quat_command_wxyz[0]"]),
    ("solver_tolerance_mm", math.nan, ["solver_tolerance_mm"]),
    ("predicted_error_mm", math.inf, ["predicted_error_mm"]),
    ("predicted_error_mm", -0.1, ["predicted_error_mm"]),
    ("predicted_rot_err_deg", math.inf, ["predicted_rot_err_deg"]),
    ("quat_command_wxyz", (0.5, 0.0, 0.0, 0.0), ["norm 0.5"]),
    ("confdata", (0, 0, 0.5, 1), ["confdata"]),
    ("q_corrected_deg", (0.0,) * 5, ["5 values, expected 6"]),
    ("target_id", "bad\nid", ["control character"]),
    ("target_id", "", ["non-empty"]),
])
def test_malformed_or_non_finite_targets_are_rejected(field, value, words):
    bad = dataclasses.replace(make_targets(1)[0], **{field: value})
    accepted, rejected = check([bad])
    assert accepted == [] and len(rejected) == 1
    for word in words:
        assert word in rejected[0].reason
    assert "\n" not in rejected[0].reason


def test_nan_predicted_errors_are_allowed():
    t = dataclasses.replace(make_targets(1)[0], predicted_rot_err_deg=math.nan, predicted_error_mm=math.nan)
    assert check([t]) == ([t], [])


def test_duplicate_id_is_rejected_after_the_first():
    t1, t2 = make_targets(2)
    t2 = dataclasses.replace(t2, target_id=t1.target_id)
    accepted, rejected = check([t1, t2])
    assert accepted == [t1] and rejected[0].reason.startswith("duplicate target id")


@pytest.mark.parametrize("kwargs", [
    dict(q_min_deg=Q_MAX, q_max_deg=Q_MIN),
    dict(q_min_deg=Q_MIN[:5]),
    dict(max_joint_correction_deg=-1.0),
    dict(max_joint_correction_deg=math.nan),
    dict(max_position_correction_mm=1.0),  # without p_target_base_mm
])
def test_bad_bound_arguments_raise(kwargs):
    args = dict(q_min_deg=Q_MIN, q_max_deg=Q_MAX, max_joint_correction_deg=1.0) | kwargs
    with pytest.raises(ValueError):
        bounds.check_targets(make_targets(2), **args)


def test_nothing_rejected_is_written_by_any_writer(tmp_path):
    targets = make_targets(10, seed=7, ids=[f"T{k:02d}" for k in range(10)])
    q = list(targets[3].q_corrected_deg)
    q[0] = 181.0
    targets[3] = dataclasses.replace(targets[3], q_corrected_deg=tuple(q))
    targets[5] = dataclasses.replace(targets[5], p_command_base_mm=(math.nan, 0.0, 0.0))
    q = list(targets[8].q_nominal_deg)
    q[4] += 3.0
    targets[8] = dataclasses.replace(targets[8], q_nominal_deg=tuple(q))
    accepted, rejected = check(targets)
    assert [r.target_id for r in rejected] == ["T03", "T05", "T08"]
    paths = write_all(tmp_path, accepted)
    target_csv.write_rejected_csv(tmp_path / "rejected.csv", rejected)
    for path in paths.values():
        text = path.read_text(encoding="utf-8")
        for r in rejected:
            assert r.target_id not in text, (path.name, r.target_id)
        for t in accepted:
            assert t.target_id in text
    rows = csv.DictReader((tmp_path / "rejected.csv").read_text().splitlines())
    assert {r["target_id"] for r in rows} == {"T03", "T05", "T08"}


@pytest.mark.parametrize("writer", ["rapid", "ur_json", "urscript", "csv"])
def test_writers_refuse_targets_outside_their_limits(tmp_path, writer):
    targets = make_targets(4)
    q = list(targets[2].q_corrected_deg)
    q[5] = 401.0
    targets[2] = dataclasses.replace(targets[2], q_corrected_deg=tuple(q))
    fn = {"rapid": rapid_module.write_rapid_module, "ur_json": ur_program.write_ur_json, "urscript": ur_program.write_urscript,
          "csv": target_csv.write_targets_csv}[writer]
    path = tmp_path / "out"
    with pytest.raises(ValueError, match=r"j6 corrected 401 deg outside limits"):
        fn(path, targets, **LIMITS)
    assert not path.exists() and list(tmp_path.iterdir()) == []
    # tighter limits given to the writer than to the check: still refused
    good = make_targets(4)
    narrow_max = tuple(min(max(t.q_corrected_deg[j] for t in good) - 1e-3, Q_MAX[j]) for j in range(6))
    with pytest.raises(ValueError, match="outside limits"):
        fn(path, good, q_min_deg=Q_MIN, q_max_deg=narrow_max)
    assert not path.exists()


@pytest.mark.parametrize("bad", [
    lambda t: dataclasses.replace(t, solver_tolerance_mm=math.nan),
    lambda t: dataclasses.replace(t, quat_command_wxyz=(0.0, 0.0, 0.0, 0.0)),
    lambda t: "not a target",
])
def test_writers_refuse_invalid_targets_and_keep_the_old_file(tmp_path, bad):
    targets = make_targets(3)
    paths = write_all(tmp_path, targets)
    before = {name: p.read_bytes() for name, p in paths.items()}
    broken = targets[:1] + [bad(targets[1])] + targets[2:]
    for name, fn in (("rapid", rapid_module.write_rapid_module), ("ur_json", ur_program.write_ur_json),
                     ("urscript", ur_program.write_urscript), ("csv", target_csv.write_targets_csv)):
        with pytest.raises(ValueError, match="refusing to write"):
            fn(paths[name], broken, **LIMITS)
        assert paths[name].read_bytes() == before[name]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(p.name for p in paths.values())


def test_writers_refuse_duplicate_ids(tmp_path):
    t1, t2 = make_targets(2)
    with pytest.raises(ValueError, match="duplicate"):
        target_csv.write_targets_csv(tmp_path / "t.csv", [t1, dataclasses.replace(t2, target_id=t1.target_id)], **LIMITS)


# --------------------------------------------------------------------------
# RAPID


@pytest.mark.parametrize("persistent", [False, True])
def test_written_rapid_module_passes_the_syntax_check(tmp_path, persistent):
    targets = make_targets(25, seed=3)
    path = rapid_module.write_rapid_module(tmp_path / "CalTargets.mod", targets, persistent=persistent, **LIMITS)
    text = path.read_text(encoding="ascii")
    assert rapid.check_rapid_syntax(text) == []
    assert text.startswith("MODULE CalTargets\n") and text.endswith("ENDMODULE\n")
    storage = "PERS" if persistent else "CONST"
    for decl in ("jointtarget jt_cal{25}:=[", "robtarget rt_cal{25}:=[", "string id_cal{25}:=[",
                 "num err_cal_mm{25}:=["):
        assert f"    {storage} {decl}" in text
    assert "CONST num n_cal:=25;" in text
    assert max(len(line) for line in text.split("\n")) <= literals.RAPID_MAX_LINE
    assert "9E9" in text and not re.search(r"\d+\.\d*e", text.lower())


def test_rapid_external_axes(tmp_path):
    targets = make_targets(3)
    text = rapid_module.render_rapid_module(targets, external_axes=[1500.25, -30.5], **LIMITS)
    data = rapid.parse_rapid_module(text)
    assert all(jt[1] == [1500.25, -30.5, 9e9, 9e9, 9e9, 9e9] for jt in data["jt_cal"])
    assert all(rt[3] == [1500.25, -30.5, 9e9, 9e9, 9e9, 9e9] for rt in data["rt_cal"])
    per_target = {t.target_id: [100.0 * k] for k, t in enumerate(targets)}
    data = rapid.parse_rapid_module(rapid_module.render_rapid_module(targets, external_axes=per_target, **LIMITS))
    assert [jt[1][0] for jt in data["jt_cal"]] == [0, 100, 200]
    with pytest.raises(ValueError):
        rapid_module.render_rapid_module(targets, external_axes={targets[0].target_id: [1.0]}, **LIMITS)
    with pytest.raises(ValueError):
        rapid_module.render_rapid_module(targets, external_axes=[0.0] * 7, **LIMITS)


def test_rapid_round_trip_to_written_precision(tmp_path):
    targets = make_targets(len(TRICKY_IDS) + 20, seed=11, ids=list(TRICKY_IDS) + [f"R{k}" for k in range(20)])
    path = rapid_module.write_rapid_module(tmp_path / "m.mod", targets, module_name="Cal_2024_Cell3", **LIMITS)
    data = rapid.parse_rapid_module(path.read_text(encoding="ascii"))
    assert list(data) == ["n_cal", "id_cal", "jt_cal", "rt_cal", "err_cal_mm"]
    assert data["n_cal"] == len(targets)
    assert data["id_cal"] == [t.target_id for t in targets]
    for t, jt, rt, err in zip(targets, data["jt_cal"], data["rt_cal"], data["err_cal_mm"]):
        assert np.allclose(jt[0], t.q_corrected_deg, rtol=0, atol=0.5e-6 + 1e-12)
        assert jt[1] == [9e9] * 6
        assert np.allclose(rt[0], t.p_command_base_mm, rtol=0, atol=0.5e-4 + 1e-9)
        q = np.asarray(t.quat_command_wxyz) / np.linalg.norm(t.quat_command_wxyz)
        assert np.allclose(rt[1], q, rtol=0, atol=0.5e-9 + 1e-15)
        assert abs(np.linalg.norm(rt[1]) - 1.0) <= 1e-8
        assert rt[2] == list(t.confdata) and all(isinstance(c, int) for c in rt[2])
        assert rt[3] == [9e9] * 6
        assert abs(err - t.predicted_error_mm) <= 0.5e-4 + 1e-12


def test_an_unknown_predicted_error_is_said_so_in_every_format(tmp_path):
    targets = [dataclasses.replace(t, predicted_error_mm=math.nan) for t in make_targets(3)]
    paths = write_all(tmp_path, targets)
    text = paths["rapid"].read_text()
    assert "err_cal_mm" not in rapid.parse_rapid_module(text) and "predicted position error is unknown" in text
    assert [d["predicted_error_mm"] for d in json.loads(paths["ur_json"].read_text())["targets"]] == [None] * 3
    assert paths["urscript"].read_text().count("predicted_error_mm=unknown") == 3
    assert all(math.isnan(t.predicted_error_mm) for t in target_csv.read_corrected_targets_csv(paths["csv"]))
    mixed = make_targets(3)                  # one unknown: no array rather than an invented number for that target
    mixed[1] = targets[1]
    assert "err_cal_mm" not in rapid.parse_rapid_module(rapid_module.render_rapid_module(mixed, **LIMITS))


def test_rapid_quaternion_is_renormalised():
    t = dataclasses.replace(make_targets(1)[0], quat_command_wxyz=(0.5000004, 0.5, 0.5, 0.5))
    rt = rapid.parse_rapid_module(rapid_module.render_rapid_module([t], **LIMITS))["rt_cal"][0]
    assert abs(math.fsum(c * c for c in rt[1]) - 1.0) <= 2e-8


@pytest.mark.parametrize("kwargs, match", [
    (dict(module_name="1Cal"), "bad identifier"),
    (dict(module_name="MODULE"), "reserved"),
    (dict(module_name="C" * 33), "longer than 32"),
])
def test_rapid_bad_module_name(kwargs, match):
    with pytest.raises(ValueError, match=match):
        rapid_module.render_rapid_module(make_targets(2), **kwargs, **LIMITS)


@pytest.mark.parametrize("tid", ["x" * 81, "snow\u2603"])
def test_rapid_refuses_ids_it_cannot_hold(tid):
    with pytest.raises(ValueError):
        rapid_module.render_rapid_module(make_targets(1, ids=[tid]), **LIMITS)


def test_rapid_needs_six_joints_and_targets():
    with pytest.raises(ValueError):
        rapid_module.render_rapid_module([], **LIMITS)
    with pytest.raises(ValueError):
        rapid_module.render_rapid_module(make_targets(1), q_min_deg=Q_MIN + (-1.0,), q_max_deg=Q_MAX + (1.0,))


VALID_MODULE = r'''%%%
  VERSION:1
  LANGUAGE:ENGLISH
%%%
MODULE Demo(SYSMODULE, NOSTEPIN)
    ! data of every checked type
    CONST num a{3}:=[1, 2.5, -3E2];
    CONST num m{2,3}:=[[1,2,3],[4,5,6]];
    LOCAL PERS string s:="say ""hi"" \\ \41";
    TASK PERS bool flag:=TRUE;
    VAR num counter;
    CONST pos p0:=[0x1F, 0b101, .5];
    CONST jointtarget jt:=[[0,0,0,0,30,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
    CONST robtarget rt:=[[600,0,800],[0,0,1,0],[0,0,0,0],[9E+09,9E9,9E9,9E9,9E9,9E9]];
    PERS tooldata tTip:=[TRUE,[[0,0,200],[1,0,0,0]],[1.5,[0,0,100],[1,0,0,0],0,0,0]];
    PERS wobjdata wTable:=[FALSE,TRUE,"",[[1000,0,0],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];
    CONST speeddata vSlow:=[100,50,5000,1000];
    CONST zonedata zTight:=[FALSE,0.3,0.3,0.3,0.03,0.3,0.03];
    CONST num twice:=2 * a{1};
    RECORD pair
        num first;
        num second;
    ENDRECORD
    VAR pair pp:=[1,2];

    PROC main()
        VAR num i:=0;
        FOR k FROM 1 TO Dim(a, 1) DO
            IF a{k} > 0 THEN
                counter:=counter + a{k};
            ELSEIF a{k} < -100 THEN
                counter:=0;
            ELSE
                Incr counter;
            ENDIF
        ENDFOR
        WHILE i < 3 DO
            i:=i + 1;
        ENDWHILE
        IF flag counter:=1;
        TEST counter
        CASE 1, 2:
            MoveAbsJ jt, vSlow, fine, tool0\WObj:=wobj0;
        DEFAULT:
            MoveL rt, vSlow, zTight,
                tTip;
        ENDTEST
    ERROR
        RETRY;
    ENDPROC

    FUNC num half(num x)
        RETURN x / 2;
    ENDFUNC
ENDMODULE
'''


def test_checker_accepts_a_valid_hand_written_module():
    assert rapid.check_rapid_syntax(VALID_MODULE) == []
    data = rapid.parse_rapid_module(VALID_MODULE)
    assert data["a"] == [1, 2.5, -300.0] and data["m"] == [[1, 2, 3], [4, 5, 6]]
    assert data["s"] == 'say "hi" \\ A' and data["flag"] is True and data["counter"] is None
    assert data["p0"] == [31, 5, 0.5]
    assert isinstance(data["twice"], rapid.RapidExpr)
    assert data["rt"][3][0] == 9e9


def _mutate(old: str, new: str) -> str:
    assert old in VALID_MODULE, old
    return VALID_MODULE.replace(old, new, 1)


BROKEN = {
    "missing ENDMODULE": (_mutate("ENDMODULE", ""), "missing ENDMODULE"),
    "unbalanced brackets": (_mutate("[[1,2,3],[4,5,6]]", "[[1,2,3],[4,5,6]"), "unbalanced brackets"),
    "extra bracket": (_mutate("[1,2];", "[1,2]];"), "missing ';'"),
    "wrong element count": (_mutate("[[600,0,800],[0,0,1,0],[0,0,0,0],", "[[600,0,800],[0,0,1,0],"),
                            "robtarget needs 4 components, got 3"),
    "position with 2 numbers": (_mutate("[600,0,800]", "[600,0]"), "rt.trans: pos needs 3 components, got 2"),
    "jointtarget with 5 joints": (_mutate("[[0,0,0,0,30,0],", "[[0,0,0,30,0],"),
                                  "jt.robax: robjoint needs 6 components, got 5"),
    "quaternion with 3 numbers": (_mutate("[0,0,1,0]", "[0,1,0]"), "orient needs 4 components, got 3"),
    "dimension mismatch": (_mutate("a{3}", "a{4}"), "dimension mismatch: a is declared with 4 elements"),
    "2-d dimension mismatch": (_mutate("m{2,3}", "m{2,4}"), "dimension mismatch"),
    "bad identifier digit": (_mutate("CONST pos p0", "CONST pos 0p"), "bad identifier or number '0p'"),
    "bad identifier underscore": (_mutate("VAR num counter;", "VAR num _counter;"), "must start with a letter"),
    "identifier too long": (_mutate("VAR num counter;", f"VAR num {'c' * 33};"), "longer than 32"),
    "reserved word as name": (_mutate("VAR num counter;", "VAR num WHILE;"), "reserved word"),
    "missing semicolon": (_mutate("TASK PERS bool flag:=TRUE;", "TASK PERS bool flag:=TRUE"), "missing ';'"),
    "missing semicolon in routine": (_mutate("i:=i + 1;", "i:=i + 1"), "missing ';'"),
    "unknown type": (_mutate("CONST speeddata vSlow", "CONST speedata vSlow"), "unknown data type 'speedata'"),
    "unterminated string": (_mutate('wTable:=[FALSE,TRUE,"",', 'wTable:=[FALSE,TRUE,",'),
                            "unterminated string"),
    "bad string escape": (_mutate(r"\\ \41", r"\q"), "bad escape"),
    "string too long": (_mutate('"say ""hi"" \\\\ \\41"', '"' + "s" * 81 + '"'), "longer than 80"),
    "curly-brace array initialiser": (_mutate("[1, 2.5, -3E2]", "{1, 2.5, -3E2}"), "expected a value, got '{'"),
    "bool where num expected": (_mutate("vSlow:=[100,", "vSlow:=[TRUE,"), "expected a num value"),
    "number where string expected": (_mutate('[FALSE,TRUE,"",', "[FALSE,TRUE,0,"), "expected a string value"),
    "CONST without value": (_mutate("CONST num twice:=2 * a{1};", "CONST num twice;"), "needs an initial value"),
    "duplicate declaration": (_mutate("VAR num counter;", "VAR num counter;\n    VAR num COUNTER;"),
                              "already declared"),
    "missing ENDIF": (_mutate("            ENDIF\n", ""), "missing ENDIF"),
    "ENDWHILE closes FOR": (_mutate("        ENDFOR", "        ENDWHILE"), "ENDWHILE does not close FOR"),
    "missing ENDPROC": (_mutate("        RETRY;\n    ENDPROC", "        RETRY;"), "missing ENDPROC"),
    "comment inside aggregate": (_mutate("[[1,2,3],[4,5,6]]", "[[1,2,3], ! rows\n[4,5,6]]"),
                                 "comment inside a statement"),
    "text after ENDMODULE": (VALID_MODULE + "CONST num late:=1;\n", "text after ENDMODULE"),
    "no MODULE": (_mutate("MODULE Demo(SYSMODULE, NOSTEPIN)", "Demo"), "expected 'MODULE name'"),
    "PERS in routine": (_mutate("VAR num i:=0;", "PERS num i:=0;"), "module level"),
    "empty aggregate": (_mutate("vSlow:=[100,50,5000,1000]", "vSlow:=[]"), "empty aggregate"),
}


@pytest.mark.parametrize("kind", sorted(BROKEN))
def test_checker_catches_broken_modules(kind):
    text, expected = BROKEN[kind]
    errors = rapid.check_rapid_syntax(text)
    assert errors, kind
    assert any(expected in e for e in errors), errors
    assert all(re.match(r"line \d+: \S", e) and "\n" not in e for e in errors)
    with pytest.raises(ValueError, match="RAPID syntax errors"):
        rapid.parse_rapid_module(text)


def test_checker_reports_the_right_line():
    errors = rapid.check_rapid_syntax(_mutate("[0,0,1,0]", "[0,1,0]"))
    line = next(k for k, s in enumerate(VALID_MODULE.split("\n"), 1) if "CONST robtarget rt" in s)
    assert errors == [f"line {line}: rt.rot: orient needs 4 components, got 3"]


def test_checker_on_written_module_mutations(tmp_path):
    text = rapid_module.render_rapid_module(make_targets(4), **LIMITS)
    assert rapid.check_rapid_syntax(text) == []
    first_joints = re.search(r"\[\[(-?[\d.]+),", text.split("jointtarget jt_cal")[1]).group(0)
    cases = [text.replace("ENDMODULE", ""),
             text.replace(first_joints, "[[", 1),               # 5 joints
             text.replace("CONST num n_cal:=4;", "CONST num n_cal:=4"),
             text.replace("jt_cal{4}", "jt_cal{5}"),
             text.replace("robtarget rt_cal", "robtargets rt_cal")]
    for broken in cases:
        assert broken != text and rapid.check_rapid_syntax(broken)
    assert rapid.check_rapid_syntax(text, max_line_len=20)


# --------------------------------------------------------------------------
# Universal Robots


def test_ur_json_round_trip(tmp_path):
    targets = make_targets(8, seed=5, ids=list(TRICKY_IDS) + ["u1", "u2", "u3"])
    path = ur_program.write_ur_json(tmp_path / "t.json", targets, **LIMITS)
    doc = json.loads(path.read_text(encoding="ascii"))
    assert doc["format"] == "ur-joint-targets/2"
    assert doc["units"] == {"q": "rad", "predicted_error": "mm", "predicted_std": "mm", "solver_tolerance": "mm"}
    assert [d["id"] for d in doc["targets"]] == [t.target_id for t in targets]
    for t, d in zip(targets, doc["targets"]):
        assert set(d) == {"id", "q_rad", "q_deg", "q_nominal_rad", "predicted_error_mm", "predicted_std_mm",
                          "solver_tolerance_mm"}
        assert d["q_deg"] == list(t.q_corrected_deg)
        assert np.allclose(np.degrees(d["q_rad"]), t.q_corrected_deg, rtol=0, atol=1e-12)
        assert np.allclose(np.degrees(d["q_nominal_rad"]), t.q_nominal_deg, rtol=0, atol=1e-12)
        assert d["predicted_error_mm"] == t.predicted_error_mm and d["solver_tolerance_mm"] == t.solver_tolerance_mm


def test_urscript_is_sane(tmp_path):
    targets = make_targets(6, seed=9, ids=["a#1", "caf\u00e9", "w", "x", "y", "z"])
    path = ur_program.write_urscript(tmp_path / "cal.script", targets, a_rad_s2=0.8, v_rad_s=0.25, **LIMITS)
    text = path.read_text(encoding="utf-8")
    assert ur_program.check_urscript_syntax(text) == []
    lines = [s.strip() for s in text.split("\n")]
    assert "def cal_targets():" in lines and lines[-2:] == ["end", ""]
    moves = [s for s in lines if s.startswith("movej(")]
    assert len(moves) == len(targets)
    for t, move in zip(targets, moves):
        comment = lines[lines.index(move) - 1]
        assert comment == f"# {t.target_id} predicted_error_mm={literals.fixed_literal(t.predicted_error_mm, 4)}"
        m = re.fullmatch(r"movej\(\[([^\]]*)\], a=0\.8, v=0\.25\)", move)
        q = [float(v) for v in m.group(1).split(",")]
        assert np.allclose(np.degrees(q), t.q_corrected_deg, rtol=0, atol=np.degrees(0.5e-9) + 1e-9)


@pytest.mark.parametrize("kwargs", [dict(a_rad_s2=0.0), dict(v_rad_s=4.0), dict(v_rad_s=math.nan),
                                    dict(name="end"), dict(name="1x")])
def test_urscript_bad_arguments(kwargs):
    with pytest.raises(ValueError):
        ur_program.render_urscript(make_targets(2), **kwargs, **LIMITS)


@pytest.mark.parametrize("text, expected", [
    ("def f():\n  movej([0,0,0,0,0,0], a=1, v=1)\n", "not closed"),
    ("def f():\n  movej([0,0,0,0,0,0, a=1, v=1)\nend\n", "unbalanced"),
    ("def f():\n  movej([nan,0,0,0,0,0], a=1, v=1)\nend\n", "non-finite"),
    ("def f():\n  x = 1e999\nend\n", "non-finite"),
    ("def f():\nend\nend\n", "without an open block"),
    ("def f():\n  else:\nend\n", "outside an if"),
    ("def f()\nend\n", "malformed"),
])
def test_urscript_checker_catches_problems(text, expected):
    errors = ur_program.check_urscript_syntax(text)
    assert any(expected in e for e in errors), errors


def test_urscript_checker_accepts_blocks():
    text = ("def f():\n  # comment with ( and nan\n  if x > 1:\n    y = 2\n  elif x < 0:\n    y = 3\n"
            "  else:\n    y = \"#(\"\n  end\n  while True:\n    sleep(0.1)\n  end\nend\n")
    assert ur_program.check_urscript_syntax(text) == []


# --------------------------------------------------------------------------
# CSV


def test_targets_csv_round_trip(tmp_path):
    targets = make_targets(9, seed=13, ids=list(TRICKY_IDS) + ["c1", "c2", "c3", "c4"])
    path = target_csv.write_targets_csv(tmp_path / "targets.csv", targets, **LIMITS)
    header = path.read_text(encoding="utf-8").split("\n")[0]
    assert header == ("target_id,q1,q2,q3,q4,q5,q6,q1_nominal,q2_nominal,q3_nominal,q4_nominal,q5_nominal,"
                      "q6_nominal,x_cmd,y_cmd,z_cmd,qw,qx,qy,qz,cf1,cf4,cf6,cfx,predicted_error_mm,"
                      "predicted_rot_err_deg,solver_tolerance_mm,predicted_std_mm")
    back = target_csv.read_corrected_targets_csv(path)
    assert len(back) == len(targets)
    for a, b in zip(targets, back):
        assert dataclasses.replace(a, predicted_rot_err_deg=0.0) == dataclasses.replace(b, predicted_rot_err_deg=0.0)
        assert (math.isnan(a.predicted_rot_err_deg) and math.isnan(b.predicted_rot_err_deg)) \
            or a.predicted_rot_err_deg == b.predicted_rot_err_deg


def test_targets_csv_other_joint_counts(tmp_path):
    t = make_targets(1)[0]
    t4 = dataclasses.replace(t, q_nominal_deg=t.q_nominal_deg[:4], q_corrected_deg=t.q_corrected_deg[:4])
    path = target_csv.write_targets_csv(tmp_path / "t.csv", [t4], q_min_deg=Q_MIN[:4], q_max_deg=Q_MAX[:4])
    back = target_csv.read_corrected_targets_csv(path)[0]
    assert back.q_corrected_deg == t4.q_corrected_deg and back.q_nominal_deg == t4.q_nominal_deg
    assert "q4_nominal,x_cmd" in path.read_text()
    with pytest.raises(ValueError):
        ur_program.write_ur_json(tmp_path / "t.json", [t4], q_min_deg=Q_MIN[:4], q_max_deg=Q_MAX[:4])


def test_rejected_csv(tmp_path):
    rejected = [Rejected("P1", "j2 corrected 200 deg outside limits [-95, 155] deg"),
                Rejected('odd,"id"', "multi\nline reason")]
    path = target_csv.write_rejected_csv(tmp_path / "rejected.csv", rejected)
    rows = list(csv.reader(path.read_text().splitlines(keepends=True)))
    assert rows == [["target_id", "reason"], [rejected[0].target_id, rejected[0].reason],
                    ['odd,"id"', "multi line reason"]]


# --------------------------------------------------------------------------
# determinism and atomicity


def test_output_is_deterministic(tmp_path):
    targets = make_targets(15, seed=21)
    first = write_all(tmp_path, targets, "-1")
    second = write_all(tmp_path, list(targets), "-2")
    rapid_module.write_rapid_module(tmp_path / "p1.mod", targets, persistent=True, **LIMITS)
    rapid_module.write_rapid_module(tmp_path / "p2.mod", targets, persistent=True, **LIMITS)
    for name in first:
        assert first[name].read_bytes() == second[name].read_bytes(), name
    assert (tmp_path / "p1.mod").read_bytes() == (tmp_path / "p2.mod").read_bytes()
    # rewriting a file in place gives the same bytes and leaves no temporary file
    rapid_module.write_rapid_module(first["rapid"], targets, **LIMITS)
    assert first["rapid"].read_bytes() == second["rapid"].read_bytes()
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]
