"""How a campaign's joint vector maps onto an ABB controller's axes: a RAPID ``jointtarget`` holds six robot axes
(``robax``, ``rax_1..rax_6``) and six external axes (``extax``, ``eax_a..eax_f``; 9E9 unused).

* a 6-axis arm: joints 1-6 are ``rax_1..rax_6``;
* a 6-axis arm on a track (the track is joint 1 of the chain, its own mechanical unit coordinated with the robot):
  the carriage (mm) is ``eax_a``, joints 2-7 are ``rax_1..rax_6``;
* a seven-axis arm (YuMi, IRB 14050): the chain lists the joints in physical order, ABB numbers them 1, 2, 7, 3, 4,
  5, 6: the physical third joint is ABB's axis 7, carried in ``eax_a`` of a jointtarget; in a robtarget ``eax_a``
  carries the arm angle instead (deg).

Other joint counts have no ABB layout here (``abb_axes`` raises ValueError with the reason).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

SEVEN_AXIS_ROBAX = (0, 1, 3, 4, 5, 6)     # chain joints (0-based, physical order) in rax_1..rax_6 of a YuMi arm


@dataclass(frozen=True)
class AbbAxes:
    """``layout`` arm | track | seven; ``n`` joints of the chain."""
    layout: str
    n: int

    def split(self, q: Sequence[float]) -> tuple[list[float], list[float]]:
        """(robax (6), extax (0 or 1)) of the chain's joint vector q (deg; a track in mm)."""
        q = [float(v) for v in q]
        if len(q) != self.n:
            raise ValueError(f"expected {self.n} joint values, got {len(q)}")
        if self.layout == "track":
            return q[1:], [q[0]]
        if self.layout == "seven":
            return [q[i] for i in SEVEN_AXIS_ROBAX], [q[2]]
        return q, []

    def join(self, robax: Sequence[float], extax: Sequence[float]) -> tuple[float, ...]:
        """The chain's joint vector from a jointtarget's robot and external axes (the inverse of ``split``)."""
        rob = [float(v) for v in robax]
        if self.layout == "track":
            return (float(extax[0]), *rob[:6])
        if self.layout == "seven":
            return (rob[0], rob[1], float(extax[0]), *rob[2:6])
        return tuple(rob[:self.n])

    @property
    def external(self) -> int:
        """How many external axes the layout uses (eax_a onwards)."""
        return 0 if self.layout == "arm" else 1


def axes_layout(n_joints: int, track: bool = False) -> AbbAxes:
    """The layout of an n-joint chain (``track``: joint 1 is a linear track); ValueError when ABB has none."""
    if track:
        if n_joints != 7:
            raise ValueError(f"an ABB robot on a track is a 6-axis arm plus the track (7 joints), got {n_joints}")
        return AbbAxes("track", 7)
    if n_joints == 7:
        return AbbAxes("seven", 7)
    if not 1 <= n_joints <= 6:
        raise ValueError(f"an ABB arm has 1 to 7 axes, got {n_joints} joints")
    return AbbAxes("arm", n_joints)
