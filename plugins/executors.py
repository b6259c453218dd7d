"""Built-in batch executors: local process pool (default), serial, Dask distributed."""
from pipeline import hookimpl
from pipeline.executor import DaskExecutor, LocalExecutor, SerialExecutor


@hookimpl
def mcl_executors():
    return [LocalExecutor, SerialExecutor, DaskExecutor]
