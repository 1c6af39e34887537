// replaced by the FEM library
