"""cipstack: the Common Industrial Protocol for AC drives over EtherNet/IP and CompoNet."""

__version__ = "0.1.0"
