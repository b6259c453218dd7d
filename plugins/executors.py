"""Built-in batch executors: local process pool (default), serial, Dask distributed."""
from mcl import hookimpl
from mcl.executor import DaskExecutor, LocalExecutor, SerialExecutor

_WORKERS = {"type": "integer", "minimum": 1, "description": "tasks run at the same time"}


@hookimpl
def mcl_executors():
    return [LocalExecutor, SerialExecutor, DaskExecutor]


@hookimpl
def mcl_option_schemas():
    return {"executor": {
        "local": {"type": "object", "properties": {"workers": _WORKERS}, "additionalProperties": False},
        "serial": {"type": "object", "properties": {}, "additionalProperties": False},
        "dask": {"type": "object", "additionalProperties": False, "properties": {
            "workers": _WORKERS,
            "address": {"type": "string", "minLength": 1,
                        "description": "scheduler address, e.g. tcp://host:8786"}}},
    }}
