// Hertz validation (docs/validation.md): the indenter, the lower half of a sphere of radius
// R = 10 mm whose pole touches the block's top face at the origin (zero gap); its flat top
// (z = 10 mm) is driven by the device. Refined towards the pole like hertz_block.geo
// (Mesh.MeshSizeMax / 16 within 3 mm). Lengths in mm.
// Groups: "sphere" (volume), "top" (driven), "cap" (the spherical cap below z = 1.2 mm,
// radius 4.8 mm: the contact face; the volume is split there, conformally).
SetFactory("OpenCASCADE");
Sphere(1) = {0, 0, 10, 10};
Box(2) = {-11, -11, 10, 22, 22, 11};
BooleanDifference(3) = { Volume{1}; Delete; }{ Volume{2}; Delete; };
Rectangle(5) = {-11, -11, 1.2, 22, 22};
BooleanFragments{ Volume{3}; Delete; }{ Surface{5}; Delete; }
interface[] = Surface In BoundingBox{-4.8, -4.8, 1.19, 4.8, 4.8, 1.21};
outside[] = Surface In BoundingBox{-11.1, -11.1, 1.19, 11.1, 11.1, 1.21};
outside[] -= interface[];
Recursive Delete { Surface{outside[]}; }
vols[] = Volume{:};
pole[] = Point In BoundingBox{-0.01, -0.01, -0.01, 0.01, 0.01, 0.01};
h = Mesh.MeshSizeMax;
Field[1] = Distance;
Field[1].PointsList = {pole[]};
Field[2] = Threshold;
Field[2].InField = 1;
Field[2].SizeMin = h / 16;
Field[2].SizeMax = h;
Field[2].DistMin = 3;
Field[2].DistMax = 15;
Background Field = 2;
Mesh.MeshSizeExtendFromBoundary = 0;
Mesh.MeshSizeFromPoints = 0;
Mesh.MeshSizeFromCurvature = 0;
Physical Volume("sphere") = {vols[]};
top[] = Surface In BoundingBox{-10.1, -10.1, 9.99, 10.1, 10.1, 10.01};
cap[] = Surface In BoundingBox{-5, -5, -0.01, 5, 5, 1.21};
cap[] -= interface[];
Physical Surface("top") = {top[]};
Physical Surface("cap") = {cap[]};
