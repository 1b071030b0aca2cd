"""openrails_bridge."""
