"""The ACG AC drive with its ACG-ET2 EtherNet/IP and Modbus TCP card.

``registers`` declares the drive's register map (ACG RS-485 manual, chapter 5, and ACG-ET2 manual, appendix
B) once; ``drive`` is the time-driven simulation of the drive behind those registers.
"""
