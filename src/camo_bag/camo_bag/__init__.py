"""Recording, replaying and rendering camouflage runs as MCAP bags."""
