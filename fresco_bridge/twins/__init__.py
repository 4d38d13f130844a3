"""Updatable sites: a twin served over the element protocol, its force learned online from an
experimental site of the same bridge in a worker process (``docs/architecture.md``, "Updatable
sites")."""
