"""RWS emulator: the thread that plays CalServer.mod (a mixin of ``RwsEmulator``)."""

from __future__ import annotations

import logging
import time

from drivers.rapid.values import Symbol, parse_literal, render

from .rws_http import ENTRY, EmulatedMotionFault, UNUSED, Fault

log = logging.getLogger("drivers.emulators.rws_server")


class CalServerMixin:
    """Serves cal_req_seq requests like the RAPID module: ack, move, settle, done or error."""

    # -- the simulated CalServer loop

    def _calserver_loop(self) -> None:
        """Plays CalServer.mod: wait for a new request, ack it, serve it (see ``_serve``)."""
        while not self._halt.is_set():
            self._wake.wait(0.005)
            self._wake.clear()
            job = self._take_request()
            if job is not None:
                try:
                    self._serve(*job)
                except Exception:                     # noqa: BLE001 - a hook failing must not kill the loop
                    log.exception("CalServer simulation failed")
                    with self._lock:
                        self._stop_program(3, 40000, "Emulator error")

    def _serving(self) -> bool:
        module = self.modules.get("calserver")
        return self.execution == "running" and self.ctrlstate == "motoron" and module is not None and \
            self._pp_reaches_calserver()

    def _pp_reaches_calserver(self) -> bool:
        """The program runs CalServer's loop: PP set to cal_run, or to a main that calls it."""
        if self.pp is None:
            return False
        module, routine = self.pp
        if routine.lower() == ENTRY:
            return True
        owner = self.modules.get(module.lower())
        return routine.lower() == "main" and owner is not None and ENTRY in owner.main_calls

    def _publish(self) -> None:
        """What cal_publish does: cal_state := [ack, done, err]."""
        syms = self.modules["calserver"].symbols
        if "cal_state" in syms:
            values = [parse_literal(syms[n].value) for n in ("cal_ack_seq", "cal_done_seq", "cal_err_seq")]
            syms["cal_state"].value = render(values)

    def _take_request(self) -> tuple | None:
        """Under the lock: resync after PP reset; if req != ack, ack it and snapshot the arguments."""
        with self._lock:
            if not self._serving() or not self.calserver_alive:
                return None
            syms = self.modules["calserver"].symbols
            num = lambda n: parse_literal(syms[n].value)  # noqa: E731
            if self._fresh_start:
                syms["cal_ack_seq"].value = syms["cal_done_seq"].value = syms["cal_req_seq"].value
                self._fresh_start = False
                self._publish()
            if num("cal_req_seq") == num("cal_ack_seq"):
                return None
            seq = num("cal_req_seq")
            syms["cal_ack_seq"].value = render(seq)
            self._publish()
            fault = self._faults.pop(0) if self._faults and num("cal_kind") in (1.0, 2.0) else None
            limits = self._limits(syms, num("cal_speed")) if int(num("cal_kind")) in (1, 2) else None
            return (seq, int(num("cal_kind")), parse_literal(syms["cal_target"].value),
                    parse_literal(syms["cal_ptarget"].value), limits, num("cal_settle_s"), fault)

    def _limits(self, syms: dict[str, Symbol], speed: list) -> dict:
        """What cal_limit does (clamp the speed to cal_vmax, VelSet) and the load in cal_tool; recorded."""
        get = lambda n, d: parse_literal(syms[n].value) if n in syms else d  # noqa: E731
        vmax, override = get("cal_vmax", 1e9), get("cal_override", 100.0)
        vmax = vmax if vmax > 0 else 1.0
        override = min(100.0, max(1.0, override))
        tool = get("cal_tool", None)
        record = {"v_tcp_programmed": speed[0], "v_leax_programmed": speed[2], "vmax": vmax, "override": override,
                  "v_tcp": min(speed[0], vmax) * override / 100.0, "v_leax": min(speed[2], vmax),
                  "load_kg": tool[2][0] if tool else None, "cog_mm": tuple(tool[2][1]) if tool else None}
        self.executed.append(record)
        return record

    def _serve(self, seq: float, kind: int, target: list, ptarget: list, limits: dict | None, settle_s: float,
               fault: Fault | None) -> None:
        if fault is not None and self._apply_fault(seq, fault):
            return
        if kind == 0:
            return self._set_done(seq)
        if kind == 1:
            reached = self._move_joints(tuple(target[0][:6]), limits["override"] / 100.0, tuple(target[1]))
        elif kind == 2:
            reached = self._move_linear(tuple(ptarget[0]), tuple(ptarget[1]), tuple(int(c) for c in ptarget[2]),
                                        tuple(ptarget[3]))
        else:
            return self._reject(seq, -1, f"CalServer: unknown request kind {kind}")
        if reached is None or not self._dwell(settle_s):
            return
        self._set_done(seq)

    def _apply_fault(self, seq: float, fault: Fault) -> bool:
        """Play an injected fault; True if the request ends here."""
        if fault.after_s and not self._dwell(fault.after_s):
            return True
        with self._lock:
            if fault.kind == "error":
                self._reject(seq, fault.code or 41617, fault.message or "CalServer: move rejected, ERRNO 41617")
            elif fault.kind == "motors_off":
                self.add_elog(3, fault.code or 20205, fault.message or "Auto stop open")
                self.set_ctrlstate("guardstop")
            elif fault.kind == "rapid_stop":
                self._stop_program(3, fault.code or 50050, fault.message or "Position outside reach")
        return True

    def _reject(self, seq: float, errno: int, message: str) -> None:
        """What ``cal_reject`` does in RAPID."""
        with self._lock:
            syms = self.modules["calserver"].symbols
            syms["cal_err_no"].value = render(float(errno))
            syms["cal_err_msg"].value = render(message[:80])
            self.add_elog(2, 80002, "CalServer request rejected", message)
            syms["cal_err_seq"].value = render(seq)
            self._publish()

    def _set_done(self, seq: float) -> None:
        with self._lock:
            syms = self.modules["calserver"].symbols
            syms["cal_reached"].value = render([list(map(float, self.joints)), list(map(float, self.ext))])
            syms["cal_done_seq"].value = render(seq)
            self._publish()

    def _move_joints(self, q: tuple[float, ...], override: float = 1.0,
                     ext: tuple[float, ...] = ()) -> tuple[float, ...] | None:
        """Interpolate to ``q`` (deg) at ``joint_speed_deg_s`` times the VelSet override, the external axes ``ext``
        (9E9: unused, left alone) with them; None if limits, a hook fault or a stop intervene."""
        for i, (v, (lo, hi)) in enumerate(zip(q, self.joint_limits)):
            if not lo <= v <= hi:
                with self._lock:
                    self._stop_program(3, 50027, "Joint Out of Range", f"axis {i + 1}: {v:g} deg not in [{lo}, {hi}]")
                return None
        with self._lock:
            start = list(self.joints)
        duration = max(abs(a - b) for a, b in zip(q, start)) / (self.joint_speed_deg_s * override)
        steps = max(1, int(duration / 0.01))
        for k in range(1, steps + 1):
            if not self._dwell(duration / steps):
                return None
            with self._lock:
                self.joints = [a + (b - a) * k / steps for a, b in zip(start, q)]
        try:
            actual = self.move_hook(q) if self.move_hook else None
        except EmulatedMotionFault as fault:
            with self._lock:
                self._stop_program(3, fault.code, fault.title)
            return None
        with self._lock:
            self.joints = [float(v) for v in (actual if actual is not None else q)]
            self.ext = [float(e) if abs(float(e)) < UNUSED / 10 else old for e, old in zip(tuple(ext) + (UNUSED,) * 6,
                                                                                          self.ext)]
            self.moves.append(("MoveAbsJ", tuple(q)))
            return tuple(self.joints)

    def _move_linear(self, trans: tuple, quat: tuple, conf: tuple, ext: tuple = ()) -> tuple[float, ...] | None:
        """MoveL: the robtarget hook may return joints; by default only the Cartesian state (and its external axes)
        changes."""
        try:
            actual = self.robtarget_hook(trans, quat, conf) if self.robtarget_hook else None
        except EmulatedMotionFault as fault:
            with self._lock:
                self._stop_program(3, fault.code, fault.title)
            return None
        with self._lock:
            self.robtarget = (list(trans), list(quat), list(conf))
            self.robtarget_ext = [float(e) for e in tuple(ext) + (UNUSED,) * (6 - len(ext))]
            if actual is not None:
                self.joints = [float(v) for v in actual]
            self.moves.append(("MoveL", tuple(trans) + tuple(quat)))
            return tuple(self.joints)

    def _dwell(self, seconds: float) -> bool:
        """Wait ``seconds`` while RAPID keeps running with motors on; False if interrupted."""
        end = time.monotonic() + max(0.0, seconds)
        while True:
            with self._lock:
                if not self._serving():
                    return False
            left = end - time.monotonic()
            if left <= 0:
                return True
            if self._halt.wait(min(left, 0.005)):
                return False
