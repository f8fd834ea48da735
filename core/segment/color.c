/* color.c: segment colours: DICOM's CIELab to sRGB, the default palette, sRGB to linear. */
#include "segment.h"

#include <math.h>

/* sRGB's transfer curve (IEC 61966-2-1) on a linear value, clipped to 0..1. */
static float encode_srgb(double c)
{
    c = c < 0 ? 0 : c > 1 ? 1 : c;
    return (float)(c <= 0.0031308 ? 12.92 * c : 1.055 * pow(c, 1 / 2.4) - 0.055);
}

/* CIE 1976 L*a*b*'s inverse of f. */
static double lab_inverse(double t)
{
    const double delta = 6.0 / 29.0;
    return t > delta ? t * t * t : 3 * delta * delta * (t - 4.0 / 29.0);
}

void iso_seg_lab_to_srgb(const uint16_t lab[3], float rgb[3])
{
    double L = lab[0] * 100.0 / 65535.0, a = lab[1] * 255.0 / 65535.0 - 128, b = lab[2] * 255.0 / 65535.0 - 128;
    double fy = (L + 16) / 116, fx = fy + a / 500, fz = fy - b / 200;
    /* D65 white, XYZ scaled so that Y = 1 is white. */
    double X = 0.95047 * lab_inverse(fx), Y = lab_inverse(fy), Z = 1.08883 * lab_inverse(fz);
    double r = 3.2404542 * X - 1.5371385 * Y - 0.4985314 * Z;
    double g = -0.9692660 * X + 1.8760108 * Y + 0.0415560 * Z;
    double bl = 0.0556434 * X - 0.2040259 * Y + 1.0572252 * Z;
    rgb[0] = encode_srgb(r);
    rgb[1] = encode_srgb(g);
    rgb[2] = encode_srgb(bl);
}

void iso_seg_default_color(size_t n, float rgb[3])
{
    /* Distinct hues of moderate lightness, like 3D Slicer's generic label colours. */
    static const unsigned char palette[][3] = {
        {128, 174, 128}, {241, 214, 145}, {177, 122, 101}, {111, 184, 210}, {216, 101, 79},
        {221, 130, 101}, {144, 238, 144}, {192, 104, 88},  {220, 245, 20},  {78, 63, 0},
        {255, 250, 220}, {230, 220, 70},  {200, 200, 235}, {250, 250, 210}, {244, 214, 49},
        {0, 151, 206},   {216, 101, 79},  {183, 156, 220}, {183, 214, 211}, {152, 189, 207}};
    const size_t count = sizeof palette / sizeof palette[0];
    for (int c = 0; c < 3; c++)
        rgb[c] = palette[n % count][c] / 255.0f;
}

float iso_seg_srgb_to_linear(float c)
{
    return c <= 0.04045f ? c / 12.92f : (float)pow((c + 0.055) / 1.055, 2.4);
}
