"""Bridges to other libraries' pose graphs (GTSAM); each imports its library only when called."""
