"""The run record: an append-only, crash-safe log of every trial, measurement and commit."""

from .export import export_csv, read_record
from .writer import RecordError, RunRecord

__all__ = ["RecordError", "RunRecord", "export_csv", "read_record"]
