"""ModelServer (seed §3.2.4): geometry database and pose filter."""

from afa.registry import not_implemented
from components.model_server.parameters import ModelServerParameters

ModelServer = not_implemented("ModelServer", ModelServerParameters, "ModelServer: geometry database and pose filter")

__all__ = ["ModelServer", "ModelServerParameters"]
