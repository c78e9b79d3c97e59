"""Errors lodprt raises for bad input (each names the file and the field it is about), a full disk, and Ctrl-C."""


class LodprtError(Exception):
    """Base class of every error lodprt raises on purpose (the CLI prints these without a traceback)."""


class SceneError(LodprtError, ValueError):
    """A scene file, mesh or scene field is missing, unreadable or out of range."""


class StoreError(LodprtError, ValueError):
    """A bake store is missing, malformed, of another format version, or would be overwritten."""


class DiskFull(StoreError):
    """The file system ran out of space while a store was written (OSError ENOSPC); the message names the store,
    what was being written and, where known, the bytes it needed."""


class Interrupted(KeyboardInterrupt):
    """Ctrl-C (SIGINT) stopped a bake; the message says what it left (the CLI prints it in one line, exit 130)."""
