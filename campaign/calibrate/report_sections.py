"""The typed sections of ``report.json`` and ``verify.json`` (frozen records): each writes the JSON object it
stands for with ``to_dict()`` (keys and order as in the file) and reads one back with ``from_dict()``
(:class:`~campaign.io.json_fields.RecordError` names a missing or ill-typed field by its path). Keys that reports of
earlier versions lack are optional when read.

Sections that another component writes stay the JSON it writes: the effect selection and fitted effects
(``robocal.effects``), the layer CV table (``robocal.layers``), the stop checks (run log events).
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from campaign.io.json_fields import (count_field, figure_field, get_field, list_field, object_field, record_dict,
                                     record_field, record_map_field, records_field, text_field, vector_field)
from robocal.identify.identification import Unidentifiable
from robocal.identify.parameters import ParameterTable
from robocal.measure.stats import ErrorStats

if TYPE_CHECKING:                                   # robocal.layers loads the GP stack: not needed to read a report
    from robocal.layers.choice import LayerChoice


@dataclass(frozen=True)
class ErrorFigures:
    """Statistics of the 3-D position error of ``n`` points (mm); None (JSON null) over no point."""
    max_mm: float | None
    mean_mm: float | None
    rms_mm: float | None
    n: int

    @classmethod
    def of(cls, stats: ErrorStats) -> "ErrorFigures":
        return cls(stats.max_mm, stats.mean_mm, stats.rms_mm, stats.n)

    def to_dict(self) -> dict:
        return record_dict(self)

    @classmethod
    def from_dict(cls, d: Mapping) -> "ErrorFigures":
        return cls(figure_field(d, "max_mm"), figure_field(d, "mean_mm"), figure_field(d, "rms_mm"), count_field(d, "n"))


NO_POINTS = ErrorFigures(None, None, None, 0)


@dataclass(frozen=True)
class PredictiveStd:
    """A GPR layer's predictive standard deviation on the test points (3-D, mm); ``per_point_mm`` {point_id: mm},
    or a reference ``{"file", "column"}`` to points.csv."""
    max_mm: float | None
    mean_mm: float | None
    rms_mm: float | None
    n: int
    per_point_mm: dict

    def to_dict(self) -> dict:
        return record_dict(self)

    @classmethod
    def from_dict(cls, d: Mapping) -> "PredictiveStd":
        f = ErrorFigures.from_dict(d)
        return cls(f.max_mm, f.mean_mm, f.rms_mm, f.n, object_field(d, "per_point_mm"))


_GP_KEYS = ("approximation", "n_train", "n_inducing", "noise_mm", "noise_floor_mm")
_CURVES = "joint_curve_rms_arcsec"
_TREND = ("trend_rms_mm", "geometry_shift_rms_mm", "trend_and_shift_rms_mm")


@dataclass(frozen=True)
class LayerSummary:
    """The fitted residual layer beside its honest figures (``robocal.layers.choice.layer_summary``): calibration RMS (a
    fit to its own points), CV-predicted held-out RMS, test RMS (mm); for a GPR its approximation, training size,
    inducing inputs (None: exact), noise and the floor bounding it (mm)."""
    kind: str
    calib_rms_mm: float | None
    cv_predicted_rms_mm: float | None
    folds: int
    test_rms_mm: float | None
    note: str
    approximation: str | None = None
    n_train: int | None = None
    n_inducing: int | None = None
    noise_mm: float | None = None
    noise_floor_mm: float | None = None
    joint_curve_rms_arcsec: Mapping[str, float] | None = None     # joint GP: each joint's curve, RMS over its range
    trend_rms_mm: float | None = None          # trend + GPR: the quadratic trend's 3-D RMS over the calibration rows
    geometry_shift_rms_mm: float | None = None  # trend + GPR: the geometry change's displacement, the same RMS
    trend_and_shift_rms_mm: float | None = None  # trend + GPR: the two together (they share directions)

    def to_dict(self) -> dict:
        out = record_dict(self)
        if self.approximation is None:                      # the GP keys come together, for a GP layer only
            for key in _GP_KEYS:
                del out[key]
        if self.joint_curve_rms_arcsec is None:
            del out[_CURVES]
        for key in _TREND:
            if out[key] is None:
                del out[key]
        return out

    @classmethod
    def from_dict(cls, d: Mapping) -> "LayerSummary":
        gp = {k: get_field(d, k, True) for k in _GP_KEYS} if "approximation" in d else {}
        if _CURVES in d:
            gp[_CURVES] = object_field(d, _CURVES)
        gp.update({k: figure_field(d, k) for k in _TREND if k in d})
        return cls(text_field(d, "kind"), figure_field(d, "calib_rms_mm"), figure_field(d, "cv_predicted_rms_mm"),
                   count_field(d, "folds"), figure_field(d, "test_rms_mm"), text_field(d, "note", True) or "", **gp)


@dataclass(frozen=True)
class HeldOutPoint:
    """A held-out point whose error is absurd against the noise floor: its id and 3-D error (mm)."""
    point_id: str
    error_mm: float

    def to_dict(self) -> dict:
        return record_dict(self)

    @classmethod
    def from_dict(cls, d: Mapping) -> "HeldOutPoint":
        return cls(text_field(d, "point_id"), figure_field(d, "error_mm"))


@dataclass(frozen=True)
class HeldOutOutliers:
    """The final model's held-out points with an absurd error (``rule`` in words, e.g. a misread), named, and the
    held-out figures ``without`` them. They stay in every other figure: never silently dropped."""
    rule: str
    points: tuple[HeldOutPoint, ...]
    without: ErrorFigures

    def to_dict(self) -> dict:
        return record_dict(self)

    @classmethod
    def from_dict(cls, d: Mapping) -> "HeldOutOutliers":
        return cls(text_field(d, "rule"), records_field(d, "points", HeldOutPoint.from_dict),
                   record_field(d, "without", ErrorFigures.from_dict))


@dataclass(frozen=True)
class StageResult:
    """One calibration stage evaluated on the ``test`` and ``calib`` rows; the final stage also carries the GPR
    predictive spread, the residual layer's summary and its absurd held-out points when it has them."""
    test: ErrorFigures
    calib: ErrorFigures
    test_pred_std_mm: PredictiveStd | None = None
    layer: LayerSummary | None = None
    test_outliers: HeldOutOutliers | None = None

    def to_dict(self) -> dict:
        return record_dict(self, omit_none=("test_pred_std_mm", "layer", "test_outliers"))

    @classmethod
    def from_dict(cls, d: Mapping) -> "StageResult":
        return cls(record_field(d, "test", ErrorFigures.from_dict), record_field(d, "calib", ErrorFigures.from_dict),
                   record_field(d, "test_pred_std_mm", PredictiveStd.from_dict, True),
                   record_field(d, "layer", LayerSummary.from_dict, True),
                   record_field(d, "test_outliers", HeldOutOutliers.from_dict, True))


@dataclass(frozen=True)
class RowCounts:
    """Rows of the dataset by set, and the calibration rows the fit left out."""
    calib: int
    test: int
    check: int
    rejected: int

    def to_dict(self) -> dict:
        return record_dict(self)

    @classmethod
    def from_dict(cls, d: Mapping) -> "RowCounts":
        return cls(*(count_field(d, k) for k in ("calib", "test", "check", "rejected")))


@dataclass(frozen=True)
class ParameterRow:
    """An identification candidate: delta from nominal and its std (angles in deg), identified or fixed, and its
    value in the chain (None: a base entry, or a report of an earlier version). The rows of a report are those of
    its model file (:func:`parameter_rows`)."""
    name: str
    unit: str
    delta: float
    std: float | None
    identified: bool
    value: float | None = None

    def to_dict(self) -> dict:
        return record_dict(self)

    @classmethod
    def from_dict(cls, d: Mapping) -> "ParameterRow":
        return cls(text_field(d, "name"), text_field(d, "unit"), figure_field(d, "delta"), figure_field(d, "std"),
                   bool(get_field(d, "identified")), figure_field(d, "value"))


def parameter_rows(table: ParameterTable) -> tuple[ParameterRow, ...]:
    """The rows of a model's parameter record (``robocal.identify.parameters``) exactly as model.json writes them (angles in
    deg): the one conversion behind report.json ``parameters``, the terminal and the HTML tables."""
    return tuple(ParameterRow.from_dict(row) for row in table.to_dict()["rows"])


@dataclass(frozen=True)
class ExcludedPoint:
    """A point left out of the fit (``set`` calib, or any set for an SMR-triangle fault) and why."""
    point_id: str
    set: str
    reason: str

    def to_dict(self) -> dict:
        return record_dict(self)

    @classmethod
    def from_dict(cls, d: Mapping) -> "ExcludedPoint":
        return cls(text_field(d, "point_id"), text_field(d, "set", True) or "calib", text_field(d, "reason"))


def unidentifiable_from_dict(d: Mapping) -> Unidentifiable:
    """``robocal.identify.identification.Unidentifiable`` of its JSON object."""
    return Unidentifiable(text_field(d, "name"), tuple(list_field(d, "redundant_with")), text_field(d, "reason"))


@dataclass(frozen=True)
class MethodChoice:
    """The estimator and the choices the config made or left to the data."""
    estimator: str
    weights: str | None
    outliers: str | None = None
    effects: str | None = None
    residual: str | None = None
    residual_config: str | None = None
    measurement_covariance: str | None = None

    def to_dict(self) -> dict:
        return record_dict(self, omit_none=("outliers", "residual_config", "measurement_covariance"))

    @classmethod
    def from_dict(cls, d: Mapping) -> "MethodChoice":
        return cls(text_field(d, "estimator"), *(text_field(d, k, True) for k in (
            "weights", "outliers", "effects", "residual", "residual_config", "measurement_covariance")))


@dataclass(frozen=True)
class EffectCounts:
    """"taken of tried", one meaning everywhere: ``tried`` the candidates the forward selection tried (a scan over a
    joint's cyclic orders counts once, a refinement that joined the candidates once), ``taken`` the effects the
    model carries."""
    taken: int
    tried: int

    def to_dict(self) -> dict:
        return record_dict(self)


def tried_candidates(selection: Mapping) -> list[str]:
    """The candidates a selection (``robocal.effects.select.EffectSelection.to_dict``) tried, in the order first tried;
    for a report of an earlier version (trials without their candidate) the candidates offered at the start."""
    trials = selection.get("trials") or ()
    if any("candidate" not in t for t in trials):
        return list(selection.get("candidates") or ())
    return list(dict.fromkeys(t["candidate"] for t in trials))


@dataclass(frozen=True)
class EffectsReport:
    """The physical effects: the CV selection and the fitted effects as ``robocal.effects`` writes them, the
    effect parameters fixed as unidentifiable; with an elastic stage its sigma0, notes and condition number."""
    selection: dict | None
    fitted: tuple[dict, ...] = ()
    unidentifiable: tuple[Unidentifiable, ...] = ()
    sigma0: float | None = None
    notes: tuple[str, ...] | None = None
    condition_number: float | None = None

    @property
    def counts(self) -> EffectCounts | None:
        """How many candidates the selection tried and how many the model took (None without a selection)."""
        sel = self.selection
        if not sel:
            return None
        return EffectCounts(len(sel.get("taken") or ()), len(tried_candidates(sel)))

    def to_dict(self) -> dict:
        out = record_dict(self, omit_none=("sigma0", "notes", "condition_number"))
        if self.counts is not None:
            out["counts"] = self.counts.to_dict()
        return out

    @classmethod
    def from_dict(cls, d: Mapping) -> "EffectsReport":
        notes = list_field(d, "notes", True)
        return cls(object_field(d, "selection", True), tuple(list_field(d, "fitted", True) or ()),
                   records_field(d, "unidentifiable", unidentifiable_from_dict, True) or (),
                   figure_field(d, "sigma0") if "sigma0" in d else None, None if notes is None else tuple(notes),
                   figure_field(d, "condition_number") if "condition_number" in d else None)


@dataclass(frozen=True)
class ResidualChoice:
    """The residual layer chosen by k-fold CV on the calibration points: per candidate its CV RMS (mm) and its
    test against none, and the geometric model's trend + GPR layer against the model with its effects when that
    was compared (``robocal.layers.choice.WithoutEffects``)."""
    chosen: str
    folds: int
    test: str
    candidates: dict
    without_effects: dict | None = None

    @classmethod
    def of(cls, choice: LayerChoice) -> "ResidualChoice":
        d = choice.to_dict()
        return cls(d["chosen"], d["folds"], d["test"], d["candidates"], d.get("without_effects"))

    @property
    def effects_left_out(self) -> tuple[str, ...]:
        """The fitted effects the final model leaves out (its layer sits on the geometric model), else ()."""
        w = self.without_effects
        return tuple(w.get("effects") or ()) if w and w.get("chosen") else ()

    def to_dict(self) -> dict:
        return record_dict(self, omit_none=("without_effects",))

    @classmethod
    def from_dict(cls, d: Mapping) -> "ResidualChoice":
        return cls(text_field(d, "chosen"), count_field(d, "folds"), text_field(d, "test", True) or "",
                   object_field(d, "candidates"), object_field(d, "without_effects", True))


@dataclass(frozen=True)
class ResidualCV:
    """The CV figure of the chosen (else the best) layer against none: held-out RMS without and with it (mm),
    relative gain, paired t and whether it is significant."""
    folds: int
    layer: str
    rms_without_mm: float
    rms_with_mm: float
    gain: float
    t: float | None = None
    significant: bool | None = None

    @property
    def predicts_structure(self) -> bool:
        """Significant; for reports without the test, a gain above 2 %."""
        return self.significant if self.significant is not None else self.gain > 0.02

    def to_dict(self) -> dict:
        return record_dict(self, omit_none=("t", "significant"))

    @classmethod
    def from_dict(cls, d: Mapping) -> "ResidualCV":
        return cls(count_field(d, "folds"), text_field(d, "layer"), figure_field(d, "rms_without_mm"),
                   figure_field(d, "rms_with_mm"), figure_field(d, "gain"),
                   figure_field(d, "t") if "t" in d else None, get_field(d, "significant", True))


@dataclass(frozen=True)
class StopSummary:
    """``plan.stop: auto``: the rule, every refit's check (run log events: predicted curve, decision), where it
    stopped and why, the predicted and the measured held-out RMS (mm, final model on the test set)."""
    rule: str
    checks: tuple[dict, ...]
    n_calib_at_stop: int
    predicted_rms_mm: float
    measured_rms_mm: float | None
    reason: str

    @property
    def last_curve(self) -> list:
        """[[calibration points, predicted held-out RMS mm], ...] of the last refit."""
        return self.checks[-1]["curve"]

    def to_dict(self) -> dict:
        return record_dict(self)

    @classmethod
    def from_dict(cls, d: Mapping) -> "StopSummary":
        return cls(text_field(d, "rule"), tuple(list_field(d, "checks")), count_field(d, "n_calib_at_stop"),
                   figure_field(d, "predicted_rms_mm"), figure_field(d, "measured_rms_mm"), text_field(d, "reason"))


@dataclass(frozen=True)
class LearningCurve:
    """How the held-out RMS falls with the number of calibration poses (mm): ``forecast`` (logged when the run
    started: noise model + parameter priors, ``campaign.plan.learning``) and ``measured`` (the first n calibration
    points in measurement order refitted by the default process, judged on the run's test set), each ((n, mm), ...);
    the measuring time in minutes: the sequence measured, the plan's and the full grid's, all timed alike from the
    motion caps, settling and reading times (``campaign.run.eta``), and the robot time the log's clock recorded."""
    forecast: tuple[tuple[int, float], ...]
    measured: tuple[tuple[int, float], ...]
    minutes_measured: float
    minutes_planned: float | None
    minutes_grid: float | None
    minutes_logged: float | None = None

    def to_dict(self) -> dict:
        return record_dict(self)

    @classmethod
    def from_dict(cls, d: Mapping) -> "LearningCurve":
        pairs = lambda name: tuple((int(n), float(v)) for n, v in list_field(d, name))  # noqa: E731
        return cls(pairs("forecast"), pairs("measured"), figure_field(d, "minutes_measured"),
                   figure_field(d, "minutes_planned"), figure_field(d, "minutes_grid"),
                   figure_field(d, "minutes_logged") if "minutes_logged" in d else None)


@dataclass(frozen=True)
class AngleStats:
    """Orientation errors (arc seconds) over ``n`` poses, and how the poses were obtained when it matters."""
    mean: float
    rms: float
    max: float
    n: int
    source: str | None = None

    def to_dict(self) -> dict:
        return record_dict(self, omit_none=("source",))

    @classmethod
    def from_dict(cls, d: Mapping) -> "AngleStats":
        return cls(figure_field(d, "mean"), figure_field(d, "rms"), figure_field(d, "max"), count_field(d, "n"),
                   text_field(d, "source", True))


@dataclass(frozen=True)
class MultiSmrReport:
    """Multi-SMR identification (one flange offset per SMR, mm), its test figures per SMR (``smr1``...) and, with
    three SMRs, the flange orientation error on the test set; or why it was ``skipped``."""
    n_smr: int
    skipped: str | None = None
    p_flange_smr_mm: list | None = None
    sigma0: float | None = None
    converged: bool | None = None
    unidentifiable: tuple[Unidentifiable, ...] = ()
    test: dict[str, ErrorFigures] = field(default_factory=dict)
    orientation_error_arcsec: AngleStats | None = None

    def to_dict(self) -> dict:
        if self.skipped is not None:
            return {"n_smr": self.n_smr, "skipped": self.skipped}
        return record_dict(self, omit_none=("skipped", "orientation_error_arcsec"))

    @classmethod
    def from_dict(cls, d: Mapping) -> "MultiSmrReport":
        n = count_field(d, "n_smr")
        if "skipped" in d:
            return cls(n, text_field(d, "skipped"))
        return cls(n, None, list_field(d, "p_flange_smr_mm"), figure_field(d, "sigma0"), get_field(d, "converged"),
                   records_field(d, "unidentifiable", unidentifiable_from_dict, True) or (),
                   record_map_field(d, "test", ErrorFigures.from_dict),
                   record_field(d, "orientation_error_arcsec", AngleStats.from_dict, True))


@dataclass(frozen=True)
class VerifyPass:
    """One verification pass: points corrected and held (count per reason), the error over all points and over
    the corrected ones (mm, None when none was corrected), the tool orientation error with three SMRs, the
    tracker drift removed from its readings (mean translation, mm, tracker frame; None without nests)."""
    stage: str
    n_corrected: int
    n_held: int
    held: dict
    all: ErrorFigures
    corrected: ErrorFigures | None
    orientation_error_arcsec: AngleStats | None = None
    drift_translation_mm: tuple[float, float, float] | None = None

    def to_dict(self) -> dict:
        return record_dict(self, omit_none=("orientation_error_arcsec", "drift_translation_mm"))

    @classmethod
    def from_dict(cls, d: Mapping) -> "VerifyPass":
        return cls(text_field(d, "stage"), count_field(d, "n_corrected"), count_field(d, "n_held"),
                   object_field(d, "held"), record_field(d, "all", ErrorFigures.from_dict),
                   record_field(d, "corrected", ErrorFigures.from_dict, True),
                   record_field(d, "orientation_error_arcsec", AngleStats.from_dict, True),
                   vector_field(d, "drift_translation_mm", 3, True))
