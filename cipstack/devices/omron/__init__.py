"""Omron MX2 and RX inverters with their CompoNet option boards (3G3AX-MX2-CRT-E, 3G3AX-RX-CRT-E).

``models`` holds the inverter models and the option board's identity, ``registers`` the
inverter registers, function codes and trip codes the option board maps onto CIP, and
``inverter`` the time-driven simulation with the flexible-format mapping rules.
"""
