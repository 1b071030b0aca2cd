/* VectorSum, FMI 2.0 co-simulation: the model in ../../common/vectorsum.h behind the FMI 2.0 wrapper. */
#include "../../common/vectorsum.h"
#include "../../common/fmi2_cosim.c"
