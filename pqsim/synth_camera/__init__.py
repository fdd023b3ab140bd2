"""pqsim/synth_camera."""
