"""The target: the sans-I/O encapsulation sessions, the Connection Manager, the class 1 target core,
and their asyncio shells."""
