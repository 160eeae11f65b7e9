# cmake -DINPUT=FILE -DOUTPUT=HEADER -DNAME=IDENTIFIER -P embed_text.cmake: writes HEADER with
# FILE's text as a C++ raw string literal, so the page stays a readable .html in the tree.
file(READ ${INPUT} text)
string(FIND "${text}" ")previs_embed\"" clash)
if(NOT clash EQUAL -1)
    message(FATAL_ERROR "${INPUT} contains the raw-string delimiter )previs_embed\"")
endif()
file(WRITE ${OUTPUT}.tmp "#pragma once\n// Generated from ${INPUT} by embed_text.cmake; edit that file.\n\nnamespace previs {\ninline constexpr const char ${NAME}[] = R\"previs_embed(${text})previs_embed\";\n}  // namespace previs\n")
file(COPY_FILE ${OUTPUT}.tmp ${OUTPUT} ONLY_IF_DIFFERENT)
file(REMOVE ${OUTPUT}.tmp)
