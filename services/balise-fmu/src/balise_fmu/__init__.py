"""balise_fmu."""
