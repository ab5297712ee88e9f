"""The face line: its straightness and creep (estimators.face.straightness), for face alignment."""
