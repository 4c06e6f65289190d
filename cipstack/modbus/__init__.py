"""Modbus as ports of a running device: the Modbus TCP server (``tcp_server``) and the RS-485 line
of Modbus-RTU (``rtu_line``). Each is a transport shell over a drive's sans-I/O Modbus core, which the
device's family declares (``cipstack.devices.base.ModbusDrive``: ``tcp`` and ``rtu``): the register map
and its rules belong to the device, and the device never sees a socket or a tty."""
