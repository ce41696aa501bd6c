"""The Go2 on MJX: the MuJoCo model with a terrain heightfield, PD control, collision."""
