"""Fleet and world tools: router, meter, publish and listen (:mod:`.runners`, :mod:`.meter`); render and features."""
