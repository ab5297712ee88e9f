"""The longwall face digital twin: scenarios in, run directories out.

    import twin
    run = twin.run("scenarios/seed001.toml", seed=3)     # or twin.run(twin.load_scenario(path), trials=5)
    run.metrics, run.stream("imu"), run.estimate("kf_cpoem_rts")
    twin.model("scenarios/default.toml", xml="face.xml", png="face.png")   # the assembled face: MJCF, a render

`run`, `estimate`, `model` and `Run` are twin.pipeline.api's; `load_scenario` and `Scenario`
twin.config.scenario's. They are imported on first use, so `import twin` stays light.
"""

from __future__ import annotations

from importlib import import_module

import estimators  # noqa: F401  (its kernel cache stamp covers twin's kernels too: estimators.kernel_cache)

_API = {"run": "twin.pipeline.api", "estimate": "twin.pipeline.api", "model": "twin.pipeline.api",
        "Run": "twin.pipeline.api", "default_scenario": "twin.pipeline.api",
        "load_scenario": "twin.config.scenario", "Scenario": "twin.config.scenario"}
__all__ = ["Run", "Scenario", "default_scenario", "estimate", "load_scenario", "model", "run"]


def __getattr__(name: str):
    if name in _API:
        return getattr(import_module(_API[name]), name)
    raise AttributeError(f"module 'twin' has no attribute '{name}'")
