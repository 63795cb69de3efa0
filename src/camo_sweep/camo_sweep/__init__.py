"""Parameter sweeps: `./camo sweep`, `./camo errors`, `./camo bench sweep`."""
