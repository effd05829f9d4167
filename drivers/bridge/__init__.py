"""The line-protocol reference bridge (``line_bridge``): serves the tracker line protocol over TCP from a vendor
SDK's back end. It is a program (``python -m drivers.bridge.line_bridge``), not a library: it offers no names.
"""
__all__: list[str] = []
