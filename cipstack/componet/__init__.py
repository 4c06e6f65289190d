"""CompoNet: node addressing, explicit messages, cyclic I/O refresh, routing."""
