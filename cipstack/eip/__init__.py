"""EtherNet/IP: encapsulation, common packet format, sessions, target and originator."""
