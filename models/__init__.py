"""MJCF pieces (pan, support, shearer) that twin.model assembles with mujoco.MjSpec."""
