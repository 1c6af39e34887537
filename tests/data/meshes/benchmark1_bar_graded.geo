// Benchmark 1's bar (100 x 20 x 20 mm, clamped at both ends) refined towards the clamped ends,
// for a reference that converges next to them (docs/free-interaction.md, "Next to the clamps";
// scripts/clamp-reference). Element size Mesh.MeshSizeMax / fine at x = 0 and x = 100 mm,
// growing linearly to Mesh.MeshSizeMax 20 mm in: a box mesh fine enough there would be fine
// everywhere, and its dense contact compliance would not fit in memory. Lengths in mm.
// Groups: "bar" (volume), "ends" (clamped), "top" and "sides" (the faces the tool can reach
// on the paths of the study; the bottom is left out to keep the compliance small).
SetFactory("OpenCASCADE");
fine = 3;  // scripts/clamp-reference rewrites this line
Box(1) = {0, 0, 0, 100, 20, 20};
h = Mesh.MeshSizeMax;
Field[1] = MathEval;
Field[1].F = Sprintf("%g + %g * Min(1, Min(x, 100 - x) / 20)", h / fine, h - h / fine);
Background Field = 1;
Mesh.MeshSizeExtendFromBoundary = 0;
Mesh.MeshSizeFromPoints = 0;
Mesh.MeshSizeFromCurvature = 0;
Physical Volume("bar") = {1};
ends[] = Surface In BoundingBox{-0.1, -0.1, -0.1, 0.1, 20.1, 20.1};
ends[] += Surface In BoundingBox{99.9, -0.1, -0.1, 100.1, 20.1, 20.1};
Physical Surface("ends") = {ends[]};
top[] = Surface In BoundingBox{-0.1, -0.1, 19.9, 100.1, 20.1, 20.1};
sides[] = Surface In BoundingBox{-0.1, -0.1, -0.1, 100.1, 0.1, 20.1};
sides[] += Surface In BoundingBox{-0.1, 19.9, -0.1, 100.1, 20.1, 20.1};
Physical Surface("top") = {top[]};
Physical Surface("sides") = {sides[]};
