"""openrails_bridge: a Coupler participant over OpenRails' web API (lockstep or stock)."""
