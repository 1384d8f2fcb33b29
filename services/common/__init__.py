"""What every service shares: one way of configuring Zenoh."""
