/*
 * The generated symbols of the table the examples are built with, for any table: the
 * examples name `GS_SYM(_verify)`, `GS_MACRO(_N_STATE)` where a firmware of one table
 * writes `paper_verify`, `PAPER_N_STATE`.
 *
 * Build with -DGS_NAME=<prefix> -DGS_NAME_UC=<PREFIX>, the C prefix of the table's
 * config name (`gainsched export-c` names its headers <prefix>_gains.h and
 * <prefix>_control.h; `make firmware-example FW_TABLE=out/myquad.h5` passes both);
 * default: the paper table. Define GS_WITH_CONTROL before including this header for
 * the controller's header too.
 */
#ifndef GS_ANY_TABLE_H
#define GS_ANY_TABLE_H

#ifndef GS_NAME
#define GS_NAME paper
#define GS_NAME_UC PAPER
#endif

#define GS_CAT_(a, b) a##b
#define GS_CAT(a, b) GS_CAT_(a, b)
#define GS_STR_(a) #a
#define GS_STR(a) GS_STR_(a)
/* a symbol of the table: GS_SYM(_table) is paper_table */
#define GS_SYM(suffix) GS_CAT(GS_NAME, suffix)
/* a macro of the table: GS_MACRO(_N_STATE) is PAPER_N_STATE */
#define GS_MACRO(suffix) GS_CAT(GS_NAME_UC, suffix)

#include GS_STR(GS_SYM(_gains).h)
#ifdef GS_WITH_CONTROL
#include GS_STR(GS_SYM(_control).h)
#endif

#endif /* GS_ANY_TABLE_H */
