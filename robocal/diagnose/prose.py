"""Words of the diagnosis: remedies (the experiment that would reveal an effect), separating experiments of
confusable classes, and the sentence of an effect outside its physical range."""
from __future__ import annotations


REMEDY = {
    "joint_compliance": "measure with two payloads and wide J2/J3 coverage including upright poses",
    "payload_deflection": "measure with a second payload (e.g. none and the rated load), alternating in blocks",
    "gear_cyclic": "cover the joint's whole range; dense single-joint sweeps (0.05-0.2 deg) for motor-rate terms",
    "backlash": "approach the poses from random, recorded directions (or paired +/- approaches), rows in measurement "
                "order",
    "readback_lag": "keep the rows in measurement order and vary the size of the moves; log the commanded joints "
                    "(qc1..qcn) next to the read-back ones",
    "thermal_drift": "log timestamps (and temperatures) from a cold start, poses in random order over >= 2 h",
    "axis_coupling": "mount the SMR >= 50 mm off the last axis and cover the wrist's first two joints widely",
    "registration_drift": "log timestamps and re-measure 3-4 floor nests every 10-15 min",
    "track_straightness": "measure at more carriage stations spread over the whole travel",
}

DRIFT_EXPERIMENT = ("measure the poses in random order and repeat a few reference poses throughout the run (a drift "
                    "moves the repeats, a pose effect does not)")

SEPARATING_EXPERIMENT = {
    frozenset({"joint_compliance", "gear_cyclic"}): "compare poses with equal q2 and different q3 (a J2 harmonic "
    "cannot depend on q3, gravity compliance does), or measure with a second payload",
    frozenset({"payload_deflection", "gear_cyclic"}): "measure the same poses with and without the payload",
    frozenset({"backlash", "readback_lag"}): "log the commanded joints (qc1..qcn), or approach the same poses with "
    "short and long moves from both sides",
    frozenset({"thermal_drift", "registration_drift"}): "re-measure floor reference nests during the run (tracker "
    "drift moves the nests, thermal growth does not)",
    frozenset({"joint_compliance", "payload_deflection"}): "measure with two payloads in alternating blocks",
    frozenset({"joint_compliance", "thermal_drift"}): "measure the poses in random order over the whole run",
}


def separating_experiment(a: str, b: str, labels: str = "") -> str:
    """The experiment that tells effect ``a`` from ``b`` (``labels``: their labels, e.g. "gear_cyclic(J5 h1)",
    when the experiment depends on the joints)."""
    if {a, b} == {"joint_compliance", "gear_cyclic"} and not any(f"gear_cyclic(J{j}" in labels for j in (2, 3)):
        return ("measure with a second payload (compliance changes with the load, a gear error does not) and cover "
                "the gear joint's whole range")
    return SEPARATING_EXPERIMENT.get(frozenset({a, b}),
                                     "widen the range of the inputs where they differ (joints, time, payload) "
                                     "or add a second SMR for orientation")


def best_available(label: str, reading: dict) -> str:
    """"best available description: X (Y; check ...)" of an effect whose fitted values are outside their range."""
    return (f"best available description: {label} ({'; '.join(reading['outside'])}: outside the physical range; "
            f"{reading['check']})")
