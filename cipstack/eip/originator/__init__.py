"""The originator: one sans-I/O core (``core``), and the asyncio and blocking clients over it."""
