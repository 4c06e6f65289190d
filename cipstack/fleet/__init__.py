"""``cipstack fleet``: many emulated devices in one command, each on its own address.

``spec`` says which device is at which address; ``serve`` runs a set of them in one event loop;
``workers`` spreads them over processes and supervises those.
"""
