"""Stage 2, the stores: the zarr formats (docs/FORMAT.md), reading and atomic writing, nothing else. Imports only
the model (completion on read) (docs/ARCHITECTURE.md)."""

from lodprt.store.bake_store import Store, is_store, open_store
from lodprt.store.writer import StoreWriter, store_format
from lodprt.store.transfer_store import TransferStore, is_transfer_store

__all__ = ["Store", "StoreWriter", "TransferStore", "is_store", "is_transfer_store", "open_store", "store_format"]
