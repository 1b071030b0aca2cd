"""openrails_mock."""
