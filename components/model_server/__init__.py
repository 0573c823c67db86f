"""ModelServer (seed §3.2.4): geometry database and pose filter."""

from components.model_server.component import ModelServer
from components.model_server.parameters import ModelServerParameters

__all__ = ["ModelServer", "ModelServerParameters"]
