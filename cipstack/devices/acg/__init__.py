"""The ACG AC drive with its ACG-ET2 EtherNet/IP and Modbus TCP card.

``registers`` declares the drive's register map (seed 001, chapter 5, and seed 000, appendix
B) once; ``drive`` is the time-driven simulation of the drive behind those registers.
"""
