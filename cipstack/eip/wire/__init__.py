"""EtherNet/IP on the wire: encapsulation, CPF items, Connection Manager messages, identity items."""
