"""Writers of simulation results to files: Rerun ``.rrd`` and Parquet tables.

Each sink is its own module, imported lazily by whoever needs it
(``from dicetrace.sinks.rerun import write_rrd``;
``from dicetrace.sinks.parquet import write_tables``), so that importing
dicetrace never pulls in rerun or pyarrow.
"""
