"""The face: layout, the MuJoCo model, the face simulator, push-advance, haulage, the shearer's ride, published truth."""
