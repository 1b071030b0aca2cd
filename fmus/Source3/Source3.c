/* Source, FMI 3.0 co-simulation: the model in ../common/source.h behind the FMI 3.0 wrapper. */
#include "../common/source.h"
#include "../common/fmi3_cosim.c"
