"""The Raptor's components, one package each (component, parameters, codec, fake).

Each package's ``__init__`` exports the component class that the ``afa.components``
entry points in ``pyproject.toml`` name. Components not written yet are declared with
:func:`afa.registry.not_implemented`, so configuration files validate against their
parameter models and ``afa run`` reports them instead of silently skipping them.
"""
