"""The main job: designs compared on independent episodes, with a verdict that holds."""
