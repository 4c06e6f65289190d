"""Modbus as ports of a running device: the Modbus TCP server (``tcp_server``) and the RS-485 line
of Modbus-RTU (``rtu_line``). Each is a transport shell over a drive's sans-I/O Modbus core: the
register map and its rules belong to the device (``cipstack.devices.acg.modbus_core``); the device
never sees a socket or a tty."""
