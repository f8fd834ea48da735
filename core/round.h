/* round.h: doubles to floats rounded outward, so that bounds stored as floats (min, max,
 * fit error) keep "min <= level < max" and "err <= tolerance" conservative. */
#ifndef ISO_ROUND_H
#define ISO_ROUND_H

#include <math.h>

static inline float iso_float_down(double x)
{
    float f = (float)x;
    return (double)f > x ? nextafterf(f, -INFINITY) : f;
}

static inline float iso_float_up(double x)
{
    float f = (float)x;
    return (double)f < x ? nextafterf(f, INFINITY) : f;
}

#endif
