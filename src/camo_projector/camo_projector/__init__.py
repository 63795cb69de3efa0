"""The projector: publishes the background the swarm stands on."""
