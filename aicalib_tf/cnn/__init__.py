"""The corner CNN: architectures, the corner map, inference, training data, training, the model card.

The only part of the package that imports TensorFlow or Keras, and only when a model is built,
loaded or trained. Importing this package imports neither.
"""
