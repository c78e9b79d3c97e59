"""The package version, in one place below every stage (stores record it)."""

__version__ = "0.1.0"
