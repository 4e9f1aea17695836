"""Samba configuration files (TOML), installed as package data so the CLIs find them."""
