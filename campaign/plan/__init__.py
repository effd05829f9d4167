"""The measurement plan as data (``points``: plan points, sets, hash, plan.csv) and how it is built from a config
(``build``: ``build_plan`` and the grid plan; ``poses``: targets, their joints and skip reasons, check poses, nest
rounds, shared by every plan kind; ``optimal``: poses chosen from a candidate pool; ``iso9283``: the ISO 9283 cube
and its cycles), with the motion safety of every move (``motion_safety``: keep-out boxes, envelope along the swept
path, via poses, speed caps). Imports config, robocal and ``drivers.base``."""
