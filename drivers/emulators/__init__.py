"""Emulators on loopback, for the tests and the demos: an ABB controller's Robot Web Services (``rws_server`` on
``rws_http``, ``rws_auth``, ``rws_controller``, ``rws_faults``, ``rws_calserver``), a UR controller good enough for
the real ur_rtde library (``rtde_server`` on ``rtde_protocol``, ``rtde_controller``, ``rtde_sessions``;
``rtde_launch`` runs it as a subprocess), a line-protocol laser tracker (``line_tracker_server``) and a Leica emScon
tracker (``emscon_server``), with the TCP plumbing (``tcp``) and the fault deck (``faults``) they share with the
reference bridge. Each server runs as ``python -m drivers.emulators.<name>``.
"""
from drivers import lazy_exports

_HOMES = {                      # module -> the public names it holds
    "emscon_server": ("PositionSource", "parser", "serve"),
    "faults": ("FaultDeck",),
    "line_tracker_server": ("FAULT_ORDER", "Response", "encode_line", "fault_response", "join_with_seq"),
    "tcp": ("TcpServer", "wait_for_shutdown"),
}
__all__ = [name for names in _HOMES.values() for name in names]
__getattr__ = lazy_exports(__name__, _HOMES)
