"""Ready-made models given as files: FMUs from any tool, and saved compiled models."""
from pathlib import Path

from mcl import hookimpl


@hookimpl
def mcl_load_model(path: str):
    p = Path(path)
    if p.suffix.lower() == ".fmu":
        from mcl.model import FmuModel

        return FmuModel.read(p)
    if p.is_dir() and (p / "model.json").is_file():
        from mcl.model import CompiledModel

        return CompiledModel.load(p)
    return None
