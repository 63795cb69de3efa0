"""Real Droplets in the swarm: the serial link, the bridge node and an emulator."""
