"""Declarative construct schemas of I/O assemblies, per device family."""
