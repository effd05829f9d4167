"""RWS emulator: controller state resources -- panel, RAPID execution, mastership, tasks/modules/symbols, motion
system, event log and file service (a mixin of ``RwsEmulator``)."""

from __future__ import annotations

from urllib.parse import unquote

from drivers.rapid.values import (SHAPES, Module, RapidSyntaxError, Symbol, matches, parse_literal,
                                  parse_module, render)

from .rws_http import (DIR_NOT_EXIST, EXEC_STATE, E_FAIL, FILE_NOT_FOUND, ILLEGAL_ENTRYPOINT, INVALIDARG,
                       INVALID_PATH, INVALID_PROGRAMFILE, INVALID_STATE, MASTER_REJECT, MODE_REJECT, MOD_AMBNAME,
                       NO_PP, NO_SUCH_SYMBOL, RAPID_SEMANTIC_ERROR, RESOURCE_HELD, Request, Response, TASK,
                       UNRESOLVED_URL, UNUSED, VOLUMES, Holder, Reject, Session, domain_key)


class ControllerMixin:
    """The resource handlers of the routing table."""

    # -- panel, system, session

    def _get_root(self, req: Request, s: Session) -> Response:
        return self._ok(req, [{"_type": "rw-root", "_title": "rw", "name": "RWS emulator"}])

    def _logout(self, req: Request, s: Session) -> Response:
        self._drop_session(s.sid)
        self.counts["logouts"] += 1
        return Response(204, b"", [("Set-Cookie", "-http-session-=; path=/; max-age=0")])

    def _system(self, req: Request, s: Session) -> Response:
        rw = "6.16.0.0" if self.version == 1 else "7.10.0"
        return self._ok(req, [{"_type": "sys-system", "_title": "system", "rwversion": rw,
                               "name": "RWS-EMULATOR", "sysid": "{00000000-0000-0000-0000-000000000000}"}])

    def _get_ctrlstate(self, req: Request, s: Session) -> Response:
        title = "ctrlstate" if self.version == 1 else "ctrl-state"
        return self._ok(req, [{"_type": "pnl-ctrlstate", "_title": title, "ctrlstate": self.ctrlstate}])

    def _post1_ctrl(self, req: Request, s: Session) -> Response:
        if req.q("action") != "setctrlstate":
            raise Reject(400, INVALIDARG, "action")
        return self._set_ctrl(req, s)

    def _set_ctrl(self, req: Request, s: Session) -> Response:
        wanted = req.form().get("ctrl-state", "")
        if wanted not in ("motoron", "motoroff"):
            raise Reject(400, INVALIDARG, "ctrl-state")
        if wanted == "motoron" and self.opmode != "AUTO":
            raise Reject(403, MODE_REJECT, "remote motors on needs AUTO")
        if wanted == "motoron" and self.ctrlstate not in ("motoroff", "motoron"):
            raise Reject(400, INVALID_STATE, f"ctrlstate {self.ctrlstate}")
        if wanted == "motoron":
            self.ctrlstate = "motoron"
            self.add_elog(1, 10011, "Motors ON state")
        else:
            self.set_ctrlstate("motoroff")
        return Response(204)

    def _get_opmode(self, req: Request, s: Session) -> Response:
        return self._ok(req, [{"_type": "pnl-opmode", "_title": "opmode", "opmode": self.opmode}])

    def _get_speedratio(self, req: Request, s: Session) -> Response:
        return self._ok(req, [{"_type": "pnl-speedratio", "_title": "speedratio", "speedratio": str(self.speedratio)}])

    def _set_speedratio(self, req: Request, s: Session) -> Response:
        try:
            ratio = int(req.form().get("speed-ratio", ""))
        except ValueError:
            raise Reject(400, INVALIDARG, "speed-ratio") from None
        if not 0 <= ratio <= 100:
            raise Reject(400, INVALIDARG, "speed-ratio")
        self.speedratio = ratio
        return Response(204)

    # -- RAPID execution

    def _get_exec(self, req: Request, s: Session) -> Response:
        return self._ok(req, [{"_type": "rap-execution", "_title": "execution", "ctrlexecstate": self.execution,
                               "cycle": self.cycle}])

    def _post1_exec(self, req: Request, s: Session) -> Response:
        action = req.q("action") or ""
        if action not in ("start", "stop", "resetpp"):
            raise Reject(400, INVALIDARG, f"action {action}")
        return self._post2_exec(req, s, action)

    def _post2_exec(self, req: Request, s: Session, verb: str) -> Response:
        {"start": self._start, "stop": self._stop, "resetpp": self._resetpp}[verb](req, s)
        return Response(204)

    def _start(self, req: Request, s: Session) -> None:
        form = req.form()
        if self.version == 1 and any(k not in form for k in ("regain", "execmode", "cycle", "condition",
                                                              "stopatbp", "alltaskbytsp")):
            raise Reject(400, INVALIDARG, "start needs regain, execmode, cycle, condition, stopatbp, alltaskbytsp")
        if self.opmode != "AUTO":
            raise Reject(403, MODE_REJECT, "remote start needs AUTO")
        if self.ctrlstate != "motoron" or self.execution == "running":
            raise Reject(400, EXEC_STATE, f"ctrlstate {self.ctrlstate}, execution {self.execution}")
        self._require_edit(s, for_start=True)
        self._require_linked()
        if self.pp is None:
            raise Reject(400, NO_PP, "set the PP to main or to a routine")
        self.execution, self.cycle = "running", form.get("cycle", "forever")
        self.add_elog(1, 10151, "Program started")

    def _stop(self, req: Request, s: Session) -> None:
        if self.execution == "running":
            self._stop_program(1, 10125, "Program stopped", "stopped by remote client")

    def _resetpp(self, req: Request, s: Session) -> None:
        if self.execution == "running":
            raise Reject(400, EXEC_STATE, "RAPID is running")
        self._require_edit(s, explicit=self.version == 2, implicit=self._implicit(req))
        self._require_linked()
        main = next((m.name for m in self.modules.values() if m.has_main), None)
        if main is None:
            raise Reject(400, NO_PP, "no main routine")
        self.pp, self._fresh_start = (main, "main"), True
        self.add_elog(1, 10002, "Program pointer has been reset")

    def _post1_pcp(self, req: Request, s: Session, task: str) -> Response:
        if req.q("action") != "set-pp-routine":
            raise Reject(400, INVALIDARG, f"action {req.q('action')}")
        return self._post2_pcp(req, s, task)

    def _post2_pcp(self, req: Request, s: Session, task: str) -> Response:
        """PP to routine (``module`` and ``routine`` both required): stopped, edit mastership, no link error,
        a procedure without parameters."""
        if task != TASK:
            raise Reject(400 if self.version == 1 else 404, E_FAIL, "unknown task")
        if self.execution == "running":
            raise Reject(400, EXEC_STATE, "RAPID is running")
        self._require_edit(s, explicit=True, implicit=self._implicit(req))
        self._require_linked()
        form = req.form()
        module = self.modules.get(form.get("module", "").lower())
        routine = form.get("routine", "")
        if module is None or not routine:
            raise Reject(400, INVALIDARG, "module and routine are required")
        if routine.lower() not in module.routines or module.routines[routine.lower()]:
            raise Reject(400, ILLEGAL_ENTRYPOINT, f"{module.name}/{routine}")
        self.pp, self._fresh_start = (module.name, routine), True
        self.add_elog(1, 10006, "Program pointer moved to routine", f"{module.name}/{routine}")
        return Response(204)

    def _implicit(self, req: Request) -> bool:
        """RWS 2.0 ``?mastership=implicit`` accepted (unless the controller is set to refuse implicit mastership)."""
        return self.version == 2 and req.q("mastership") == "implicit" and self.implicit_mastership

    def _get_mechunits(self, req: Request, s: Session) -> Response:
        return self._ok(req, [{"_type": "ms-mechunit-li", "_title": u, "mode": m}
                              for u, m in {"ROB_1": "Activated", **self.units}.items()], collection=True)

    def _get_pcp(self, req: Request, s: Session, task: str) -> Response:
        module, routine = self.pp or ("", "")
        item = {"_type": "pcp-info", "_title": "progpointer", "beginposition": "1,1" if self.pp else "",
                "endposition": "1,1" if self.pp else "", "modulemame": module, "routinename": routine,
                "execlevel": "Normal"}
        return self._ok(req, [item])

    def link_error(self) -> str:
        """What keeps the task's program from linking (empty if it links): two ``main`` procedures, or main calling
        a procedure that no module defines."""
        mains = [m.name for m in self.modules.values() if m.has_main]
        if len(mains) > 1:
            return f"Ambiguous name main (modules {', '.join(mains)})"
        defined = {r for m in self.modules.values() for r in m.routines}
        for m in self.modules.values():
            unknown = sorted(m.main_calls - defined)
            if unknown:
                return f"Reference to unknown procedure {unknown[0]} in {m.name}"
        return ""

    def _require_linked(self) -> None:
        error = self.link_error()
        if error:
            raise Reject(400, RAPID_SEMANTIC_ERROR, error)

    def _stop_program(self, msgtype: int, code: int, title: str, desc: str = "") -> None:
        self.execution = "stopped"
        self.add_elog(msgtype, code, title, desc)

    # -- mastership

    def _get_mastership(self, req: Request, s: Session, domain: str) -> Response:
        key = self._domain(domain)
        holder = self.mastership.get(key)
        item = {"_type": "msh-resource", "_title": domain, "mastership": "nomaster", "mastershipheldbyme": "FALSE"}
        if holder is None and key == "motion" and self.execution == "running":
            item["mastership"] = "internal"          # RAPID itself holds motion while it runs
        if holder is not None:
            mine = holder.session == s.sid
            item.update(mastership="remote" if holder.session else holder.location,
                        mastershipheldbyme="TRUE" if mine else "FALSE", application=holder.application,
                        location=holder.location, uid=holder.session or "0")
        return self._ok(req, [item])

    def _post1_mastership(self, req: Request, s: Session, domain: str | None) -> Response:
        verb = req.q("action") or ""
        if verb not in ("request", "release"):
            raise Reject(400, INVALIDARG, f"action {verb}")
        return self._post2_mastership(req, s, domain, verb)

    def _post2_mastership(self, req: Request, s: Session, domain: str | None, verb: str) -> Response:
        keys = [self._domain(domain)] if domain else ["edit", "motion"] + (["cfg"] if self.version == 1 else [])
        if verb == "request":
            if self.opmode != "AUTO":
                raise Reject(403, MODE_REJECT, "mastership in manual mode needs RMMP")
            for key in keys:
                holder = self.mastership.get(key)
                if holder is not None and holder.session != s.sid:
                    self._count_foreign_refusal(key)
                    raise Reject(403, RESOURCE_HELD, f"{key} held by {holder.application}")
            for key in keys:
                self.mastership[key] = Holder(s.sid, "RWS", "remote")
        else:
            for key in keys:   # a release from a non-holder is a silent no-op
                if self.mastership.get(key) and self.mastership[key].session == s.sid:
                    del self.mastership[key]
        return Response(204)

    def _count_foreign_refusal(self, key: str) -> None:
        left = self._foreign_refusals.get(key)
        if left is not None:
            self._foreign_refusals[key] = left - 1
            if left - 1 <= 0:
                self._foreign_refusals.pop(key)
                self.mastership.pop(key, None)

    def _domain(self, domain: str) -> str:
        valid = ("rapid", "motion", "cfg") if self.version == 1 else ("edit", "motion")
        if domain not in valid:
            raise Reject(404, UNRESOLVED_URL, f"mastership domain {domain}")
        return domain_key(domain)

    def _require_edit(self, s: Session, *, explicit: bool = False, implicit: bool = False,
                      for_start: bool = False) -> None:
        """Mastership rules for RAPID edits and start (see the module docstring)."""
        holder = self.mastership.get("edit")
        if holder is not None and holder.session != s.sid:
            raise Reject(403, RESOURCE_HELD, f"edit held by {holder.application}")
        if for_start:
            if self.version == 2 and holder is not None:
                raise Reject(403, RESOURCE_HELD, "release edit mastership before start")
            return
        if explicit and holder is None and not implicit:
            raise Reject(403, MASTER_REJECT, "request mastership first")

    # -- tasks, modules, symbols

    def _get_tasks(self, req: Request, s: Session) -> Response:
        item = {"_type": "rap-task-li", "_title": TASK, "name": TASK, "type": "normal",
                "taskstate": "started" if self.modules else "empty",
                "excstate": "started" if self.execution == "running" else "stopped", "active": "On",
                "motiontask": "TRUE"}
        return self._ok(req, [item], collection=True)

    def _module_items(self) -> list[dict]:
        system = [{"_type": "rap-module-info-li", "_title": n, "name": n, "type": "SysMod"} for n in ("BASE", "user")]
        return system + [{"_type": "rap-module-info-li", "_title": m.name, "name": m.name, "type": "ProgMod"}
                         for m in self.modules.values()]

    def _get_modules1(self, req: Request, s: Session) -> Response:
        if (req.q("task") or TASK) != TASK:
            raise Reject(400, E_FAIL, "unknown task")
        return self._ok(req, self._module_items())

    def _get_modules2(self, req: Request, s: Session, task: str) -> Response:
        if task != TASK:
            raise Reject(404, UNRESOLVED_URL, "unknown task")
        return self._ok(req, self._module_items())

    def _post1_task(self, req: Request, s: Session, task: str) -> Response:
        action = req.q("action") or ""
        if action in ("activate", "deactivate"):
            return Response(204)
        if action not in ("loadmod", "unloadmod"):
            raise Reject(400, INVALIDARG, f"action {action}")
        return self._post2_task(req, s, task, action)

    def _post2_task(self, req: Request, s: Session, task: str, verb: str) -> Response:
        if task != TASK:
            raise Reject(400 if self.version == 1 else 404, E_FAIL, "unknown task")
        if self.execution == "running":
            raise Reject(400 if self.version == 1 else 403, EXEC_STATE, "Operation not allowed for current PGM state")
        self._require_edit(s, explicit=True, implicit=self._implicit(req))
        form = req.form()
        if verb == "unloadmod":
            return self._unload(form.get("module", ""))
        return self._loadmod(form.get("modulepath", ""), form.get("replace", "false").lower() == "true")

    def _loadmod(self, modulepath: str, replace: bool) -> Response:
        key = self._file_key(modulepath)
        if key not in self.files:
            raise Reject(400, FILE_NOT_FOUND, modulepath)
        try:
            module = parse_module(self.files[key].decode("latin-1"))
        except RapidSyntaxError as exc:
            self.add_elog(3, 40010, "Syntax error", str(exc))
            raise Reject(400, INVALID_PROGRAMFILE, str(exc)) from None
        if module.name.lower() in self.modules and not replace:
            raise Reject(400, MOD_AMBNAME, module.name)
        self._install(module)
        error = self.link_error()
        if error:                                  # loaded, but the program does not link (as on a controller)
            self.add_elog(3, 40192, "Link error", error)
        return Response(204)

    def _install(self, module: Module) -> None:
        self.modules[module.name.lower()] = module
        if module.has_main or (self.pp is not None and self.pp[0].lower() == module.name.lower()):
            self.pp = None

    def _unload(self, name: str) -> Response:
        module = self.modules.pop(name.lower(), None)
        if module is None:
            raise Reject(400, NO_SUCH_SYMBOL if self.version == 1 else MOD_AMBNAME, name)
        if module.has_main or (self.pp is not None and self.pp[0].lower() == module.name.lower()):
            self.pp = None
        return Response(204)

    def _find_symbol(self, task: str, first: str, second: str | None) -> Symbol:
        """``RAPID/{task}/{module}/{symbol}`` or the task-global ``RAPID/{task}/{symbol}``."""
        missing = Reject(400, E_FAIL, "symbol not found") if self.version == 1 else \
            Reject(404, NO_SUCH_SYMBOL, "symbol not found")
        if task != TASK:
            raise missing
        if second is not None:
            module = self.modules.get(first.lower())
            if module is None or second.lower() not in module.symbols:
                raise missing
            return module.symbols[second.lower()]
        for module in self.modules.values():
            sym = module.symbols.get(first.lower())
            if sym is not None and sym.storage == "PERS":
                return sym
        raise missing

    def _get_symbol(self, req: Request, s: Session, task: str, first: str, second: str | None) -> Response:
        sym = self._find_symbol(task, first, second)
        title = f"RAPID/{task}/{first}" + (f"/{second}" if second else "")
        return self._ok(req, [{"_type": "rap-data", "_title": title, "value": sym.value}])

    def _post1_symbol(self, req: Request, s: Session, task: str, first: str, second: str | None) -> Response:
        if req.q("action") != "set":
            raise Reject(400, INVALIDARG, "action")
        return self._write_symbol(req, s, self._find_symbol(task, first, second), implicit=True)

    def _post2_symbol(self, req: Request, s: Session, task: str, first: str, second: str | None) -> Response:
        sym = self._find_symbol(task, first, second)
        if req.q("mastership") == "implicit" and not self.implicit_mastership:
            holder = self.mastership.get("edit")
            if holder is None or holder.session != s.sid:
                raise Reject(403, MASTER_REJECT, "implicit mastership refused; request edit mastership")
        return self._write_symbol(req, s, sym, implicit=req.q("mastership") == "implicit" and self.implicit_mastership)

    def _write_symbol(self, req: Request, s: Session, sym: Symbol, *, implicit: bool) -> Response:
        if self.opmode != "AUTO":
            raise Reject(403, MODE_REJECT, "remote writes in manual mode need RMMP")
        self._require_edit(s, explicit=True, implicit=implicit)
        if sym.storage == "CONST":
            raise Reject(400, INVALIDARG, f"{sym.name} is a constant")
        try:
            value = parse_literal(req.form().get("value", ""))
        except RapidSyntaxError:
            raise Reject(400, INVALIDARG, "value does not parse") from None
        shape = SHAPES.get(sym.dtype)
        if shape is not None and not sym.array and not matches(value, shape):
            raise Reject(400, INVALIDARG, f"value is not a {sym.dtype}")
        sym.value = render(value)
        return Response(204)

    # -- motion system and elog

    def _get_jointtarget(self, req: Request, s: Session, mechunit: str) -> Response:
        self._check_mechunit(mechunit)
        item = {"_type": "ms-jointtarget", "_title": mechunit}        # a unit of its own: its axis in eax_a
        rob, ext = (self.joints, self.ext) if mechunit == "ROB_1" else ([UNUSED] * 6, self.ext[:1] + [UNUSED] * 5)
        item.update({f"rax_{i + 1}": render(float(v)) for i, v in enumerate(rob)})
        item.update({f"eax_{c}": render(float(v)) for c, v in zip("abcdef", ext)})
        return self._ok(req, [item])

    def _get_robtarget(self, req: Request, s: Session, mechunit: str) -> Response:
        self._check_mechunit(mechunit)
        (x, y, z), quat, conf = self.robtarget
        item = {"_type": "ms-robtargets", "_title": mechunit, "x": render(x), "y": render(y), "z": render(z)}
        item.update({f"q{i + 1}": render(float(q)) for i, q in enumerate(quat)})
        item.update(dict(zip(("cf1", "cf4", "cf6", "cfx"), (str(int(c)) for c in conf))))
        item.update({f"eax_{c}": render(float(v)) for c, v in zip("abcdef", self.robtarget_ext)})
        item.update({f"eax{c}": render(float(v)) for c, v in zip("abcdef", self.robtarget_ext)})   # [arc] reads these
        return self._ok(req, [item])

    def _check_mechunit(self, mechunit: str) -> None:
        if mechunit != "ROB_1" and mechunit not in self.units:
            raise Reject(400 if self.version == 1 else 404, -1073436668, f"no mechunit {mechunit}")

    def _get_elog(self, req: Request, s: Session, domain: str) -> Response:
        entries = list(reversed(self.elog)) if domain == "0" else []
        start = int(req.q("start") or 1)
        limit = int(req.q("limit") or 200)
        items = [self._elog_item(e) for e in entries[start - 1:start - 1 + limit]]
        return self._ok(req, items, collection=True)

    def _elog_item(self, e: dict) -> dict:
        item = {"_type": "elog-message-li", "_title": f"/rw/elog/0/{e['seqnum']}", "msgtype": str(e["msgtype"]),
                "code": str(e["code"]), "tstamp": e["tstamp"], "title": e["title"], "desc": e["desc"],
                "conseqs": "", "causes": "", "actions": "", "argc": "0"}
        if self.version == 2:
            item["_links"] = {"self": {"href": f"0/{e['seqnum']}?lang=en"}}
        return item

    def _get_identity(self, req: Request, s: Session) -> Response:
        return self._ok(req, [{"_type": "ctrl-identity-info", "_title": "identity", "ctrl-name": "RWS-EMULATOR",
                               "ctrl-type": "Virtual Controller", "ctrl-id": self.serial,
                               "mac-address": "00-00-00-00-00-00"}])

    def _get_robottype(self, req: Request, s: Session) -> Response:
        return self._ok(req, [{"_type": "sys-robottype", "_title": "robottype", "robot-type": self.robot_type}])

    def _get_options(self, req: Request, s: Session) -> Response:
        return self._ok(req, [{"_type": "sys-option-li", "_title": str(i), "option": o}
                              for i, o in enumerate(self.system_options)], collection=True)

    def _get_task_motion1(self, req: Request, s: Session, task: str) -> Response:
        resource = req.q("resource") or ""
        if resource not in ("jointtarget", "robtarget"):
            raise Reject(400, INVALIDARG, "resource")
        return self._get_task_motion2(req, s, task, resource)

    def _get_task_motion2(self, req: Request, s: Session, task: str, resource: str) -> Response:
        """The motion task's current jointtarget / robtarget (what RW7 clients read)."""
        if task != TASK:
            raise Reject(400 if self.version == 1 else 404, E_FAIL, "unknown task")
        return self._get_jointtarget(req, s, "ROB_1") if resource == "jointtarget" else \
            self._get_robtarget(req, s, "ROB_1")

    def _get_ctrl_var(self, req: Request, s: Session, name: str) -> Response:
        return self._ok(req, [{"_type": "ctrl-var", "_title": name, "_value": f"{name.strip('$')}",
                               "value": f"{name.strip('$')}"}])

    # -- file service

    def _file_key(self, path: str) -> str:
        """``$HOME/a/b.mod`` (2.0 also ``%24HOME``, ``HOME``) -> ``HOME/a/b.mod``."""
        if "%24" in path.upper() and self.version == 1:
            raise Reject(400, INVALID_PATH, "use a literal $ in the volume name")
        path = unquote(path).strip("/")
        volume, _, rest = path.partition("/")
        volume = volume[1:] if volume.startswith("$") else volume
        if volume.upper() not in VOLUMES or (self.version == 1 and not path.startswith("$")):
            raise Reject(404, DIR_NOT_EXIST if self.version == 2 else E_FAIL, "no such volume")
        return f"{volume.upper()}/{rest}".rstrip("/")

    def _get_file(self, req: Request, s: Session, raw: str) -> Response:
        key = self._file_key(raw)
        if key in self.files:
            return Response(200, self.files[key], [("Content-Type", "application/octet-stream")])
        prefix = key + "/"
        names = sorted({k[len(prefix):].split("/")[0] for k in self.files if k.startswith(prefix)})
        if "/" not in key or names:
            items = [{"_type": "fs-file", "_title": n, "fs-size": str(len(self.files.get(prefix + n, b"")))}
                     for n in names]
            return self._ok(req, items, collection=True)
        raise Reject(404, DIR_NOT_EXIST if self.version == 2 else E_FAIL, "file not found")

    def _head_file(self, req: Request, s: Session, raw: str) -> Response:
        return Response(200 if self._file_key(raw) in self.files else 404)

    def _put_file(self, req: Request, s: Session, raw: str) -> Response:
        if self.version == 2 and "v=2.0" not in req.header("Content-Type"):
            return Response(415, b"", [("Content-Type", "text/plain")])
        key = self._file_key(raw)
        existed = key in self.files
        self.files[key] = req.body
        return Response(200 if existed else 201)

    def _delete_file(self, req: Request, s: Session, raw: str) -> Response:
        if self.files.pop(self._file_key(raw), None) is None:
            raise Reject(404, DIR_NOT_EXIST if self.version == 2 else E_FAIL, "file not found")
        return Response(204)
