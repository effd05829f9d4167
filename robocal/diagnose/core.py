"""``diagnose``: base fit, candidates, forward and backward selection, result."""
from __future__ import annotations

import numpy as np

from ..identify import CalibrationOptions, calibrate
from ..kinematics import ParamLayout
from .candidates import build_candidates, nest_drift
from .engine import _Engine, _orth, _State
from .records import Diagnosis, DiagnosisInput, DiagnosisOptions
from .result import Outcome, _assemble
from .scoring import _Selector
from .selection import _backward, _forward, _outliers, _stage_summary


def _base_fit(inp: DiagnosisInput, opt: DiagnosisOptions):
    """Registration + identifiability + LM of the complete geometric model on the calibration rows."""
    cal = np.flatnonzero(inp.calib)
    res = calibrate(inp.kin, inp.q_rad[cal], inp.p_mm[cal], inp.cov_mm2[cal], CalibrationOptions(method="lm"))
    layout = ParamLayout.of(res.kinematics)
    cols = np.array([layout.index(nm) for nm in res.identified], int)
    return res, cols


def diagnose(inp: DiagnosisInput, options: DiagnosisOptions = DiagnosisOptions()) -> Diagnosis:
    """Run the whole diagnosis on one dataset (see the module docstring)."""
    opt = options
    if inp.baseline is not None and inp.baseline_identified is not None:
        kin0 = inp.baseline
        layout = ParamLayout.of(kin0)
        cols = np.array([layout.index(nm) for nm in inp.baseline_identified], int)
    else:
        res, cols = _base_fit(inp, opt)
        kin0 = res.kinematics if inp.baseline is None else inp.baseline
    eng = _Engine(inp, cols, np.flatnonzero(inp.calib), np.flatnonzero(inp.test))
    if inp.baseline is not None:              # the best geometric model as given: "before" agrees everywhere
        pred, J = eng.predict(kin0, [], np.zeros(0))
        geo_state = _State(kin0, [], np.zeros(0), pred, J)
    st = eng.fit(kin0, [])
    outliers = _outliers(eng, st, opt)
    if len(outliers):
        eng.fit_rows = np.setdiff1d(eng.fit_rows, outliers)
        st = eng.fit(st.kin, [])
    if inp.baseline is None:
        geo_state = st
    drift = (nest_drift(inp.nests, inp.noise_floor_mm, opt.nest_alpha, opt.nest_ruled_out_ratio)
             if inp.nests is not None else None)
    meta = dict(inp.meta(), nest_drift=drift, order=np.arange(len(inp.q_rad)) if inp.order is None else inp.order)
    cands = build_candidates(st.kin, inp.q_rad, meta, eng.fit_rows, st.J, st.pred, opt)
    sel = _Selector(eng, inp, opt)
    Qgeo = _orth(eng.wflat(st.J[:, :, cols], eng.fit_rows))
    stages = [_stage_summary(eng, geo_state, [], opt)]
    if st is not geo_state:
        stages[0]["refit_test_rms_mm"] = eng.test_rms(st)
    st, accepted, last_scores = _forward(eng, sel, st, cands, stages, Qgeo, opt)
    st, accepted, stages, dropped = _backward(eng, sel, st, accepted, stages, opt)
    for _ in range(opt.backward_repeats):     # what is left must pass again once the dropped effects are gone
        if not dropped or not accepted:
            break
        st, accepted, stages, more = _backward(eng, sel, st, accepted, stages, opt)
        if not more:
            break
        dropped += more
    return _assemble(inp, opt, Outcome(eng, sel, cands, geo_state, st, accepted, dropped, stages, last_scores, Qgeo,
                                       outliers))
