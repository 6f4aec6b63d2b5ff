"""Examples that use STCrowd from outside its four packages (run them from the repository root): a plug-in predictor
(``knn_predictor``) and a navigation policy package (``my_policy``)."""
