"""The visual maze's pre-trained parts (issue 21): VAE, latent store, position estimator, inverse dynamics."""
