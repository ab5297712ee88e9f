"""Scenario files shipped with longwall-twin; `default.toml` is what `longwall run` uses with no argument."""
