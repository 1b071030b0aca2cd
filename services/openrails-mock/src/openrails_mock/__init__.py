"""openrails_mock: an aiohttp server that answers like OpenRails web API, with train physics."""
