"""MJCF pieces (pan, support, shearer) that twin.face.model assembles with mujoco.MjSpec."""
