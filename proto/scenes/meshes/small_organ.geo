// A second, smaller soft organ lying on organ.geo: the lower half of an ellipsoid with
// semi-axes 18 x 14 x 9 mm, dome down, centred 8 mm off-axis in x so that its pole
// (z = 15.2 mm) is 0.5 mm above organ.geo's slope. Its flat top (z = 24.2 mm) is held by
// the device. Lengths in mm. Groups: "small_organ" (volume), "top" (driven), "skin".
SetFactory("OpenCASCADE");
Sphere(1) = {0, 0, 0, 1};
Dilate {{0, 0, 0}, {18, 14, 9}} { Volume{1}; }
Box(2) = {-30, -30, 0, 60, 60, 30};
BooleanDifference(3) = { Volume{1}; Delete; }{ Volume{2}; Delete; };
Translate {8, 0, 24.2} { Volume{3}; }
Physical Volume("small_organ") = {3};
top[] = Surface In BoundingBox{-10.1, -14.1, 24.19, 26.1, 14.1, 24.21};
all[] = Abs(Boundary{ Volume{3}; });
skin[] = all[];
skin[] -= top[];
Physical Surface("top") = {top[]};
Physical Surface("skin") = {skin[]};
