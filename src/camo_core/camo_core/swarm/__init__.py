"""The swarm runtime, beside the algorithm it runs: a robot's step protocol (`protocol`: when
it steps, waits and gives up waiting), what it takes in and gives out (`robot_io`), the
process-wide mailbox and tick schedule (`mailbox`, `ticks`), whether a process lives
(`liveness`), robots' reports as a table (`status_rows`), what a message must look like before
it is used (`validation`) and a distributed run's setup (`run_setup`). No ROS here."""
