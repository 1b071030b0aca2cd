/* StateSpace, FMI 3.0 co-simulation: the model in ../common/statespace.h (arrays) behind the
 * FMI 3.0 wrapper. */
#include "../common/statespace.h"
#include "../common/fmi3_cosim.c"
