"""Device families: identity, objects, assemblies, parameter table and drive simulation."""
