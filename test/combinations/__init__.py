"""Every shipped cell with every output, layout and fault family, checked against each other."""
