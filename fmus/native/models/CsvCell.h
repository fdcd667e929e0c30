/* Empty on purpose: the CSV code is csv_table.h (fmus/native/common). Kept only while
 * models/train/longitudinal.py, models/train/driver.py and models/inertial/trolley.py still
 * name it in c_sources (the build includes what the sources #include by itself). */
#ifndef CSV_CELL_H
#define CSV_CELL_H
#include "csv_table.h"
#endif
