"""Fleet batch identification: one row per record, run on ``dask.distributed`` (docs/fleet.md).

* ``row``: the table's columns and an empty row.
* ``job``: identify (and optionally diagnose) one record into a row; a bad
  record becomes a row that says why, never an exception.
* ``runner``: the records on a Dask cluster (a local one by default), rows as
  they finish; Dask is imported only here, when a batch runs (the ``fleet`` extra).
* ``summary``: the fleet's distributions and its outliers (robust z-score on median/MAD).
* ``table``: the rows as CSV or Parquet (pyarrow, the ``fleet`` extra).

``creep_online.io.fleet_records.find_records`` names the records.
"""
from .._lazy import lazy_attributes
from .row import COLUMNS
from .summary import flag_outliers, summarize
from .table import write_table

__all__ = ["COLUMNS", "run_record", "flag_outliers", "summarize", "write_table"]

#: ``run_record`` loads the identification (scipy, numba) on first use only.
__getattr__ = lazy_attributes(__name__, {"run_record": "job"})
