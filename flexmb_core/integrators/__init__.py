"""Time integrators (Newmark, generalized-α Arnold–Brüls) and the static load stepper."""
