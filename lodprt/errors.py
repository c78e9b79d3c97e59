"""Errors lodprt raises for bad input: each names the file and the field it is about."""


class LodprtError(Exception):
    """Base class of every error lodprt raises on purpose (the CLI prints these without a traceback)."""


class SceneError(LodprtError, ValueError):
    """A scene file, mesh or scene field is missing, unreadable or out of range."""


class StoreError(LodprtError, ValueError):
    """A bake store is missing, malformed, of another format version, or would be overwritten."""
