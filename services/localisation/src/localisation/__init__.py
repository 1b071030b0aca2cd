"""Balise-based train localisation under test: the localisation (``unit``, on the adapter SDK,
over ``estimator``) and the onboard sensor models that feed it (``odometer``, ``transmission``,
served by ``sensors``)."""
