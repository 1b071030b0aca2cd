"""Example participants: small, complete, and the template for new ones."""
