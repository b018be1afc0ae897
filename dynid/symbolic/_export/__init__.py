"""Templates and the standalone loader shipped with every C export."""
