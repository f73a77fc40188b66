"""``relaff reproduce``: the whole study in one resumable command."""
