"""The paper's experiments: every network trained with and without the augmentation, tables, figures."""
