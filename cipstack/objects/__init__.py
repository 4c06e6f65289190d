"""The standard CIP objects a device is built from."""
