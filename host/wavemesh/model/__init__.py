"""The model's stages between reading and refining: filter bank, templates, labeller, initial mesh."""
