"""Stage 2, the stores: the zarr formats (docs/FORMAT.md), reading and atomic writing, nothing else. Imports only
the model (completion on read) (docs/ARCHITECTURE.md)."""

from lodprt.store.bake_store import Store, StoreWriter, is_store, open_store, store_format

__all__ = ["Store", "StoreWriter", "is_store", "open_store", "store_format"]
