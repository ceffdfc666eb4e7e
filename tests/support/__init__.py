"""What the tests share: slow, obvious NumPy references of the kernels (``naive_*``), small cases
and their runs (``simcase``), the independent checker of written snapshots (``snapshot_checks``)
and stand-ins for the surface-field tests (``field_standins``). Imported as ``support.<module>``
(``pyproject.toml`` puts ``tests/`` on the path)."""
