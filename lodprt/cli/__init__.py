"""Stage 6, the command line (``lodprt``): one module per command family over the stages below it
(docs/ARCHITECTURE.md)."""

from lodprt.cli.main import main

__all__ = ["main"]
