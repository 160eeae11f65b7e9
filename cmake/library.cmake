# previs_add_library(NAME SOURCES src... [PUBLIC lib...] [PRIVATE lib...] [OPENCV PUBLIC|PRIVATE])
# One static library per folder (STYLE.md, layout): headers included from the tree's root, the
# project's warning set, and OpenCV's headers as SYSTEM headers, PUBLIC where OpenCV types appear
# in the folder's own headers and PRIVATE where frames cross the folder's edge as plain bytes.
function(previs_add_library name)
    cmake_parse_arguments(ARG "" "OPENCV" "SOURCES;PUBLIC;PRIVATE" ${ARGN})
    add_library(${name} STATIC ${ARG_SOURCES})
    target_include_directories(${name} PUBLIC ${CMAKE_SOURCE_DIR})
    if(ARG_OPENCV)
        target_include_directories(${name} SYSTEM ${ARG_OPENCV} ${OpenCV_INCLUDE_DIRS})
    endif()
    target_link_libraries(${name} PUBLIC ${ARG_PUBLIC} PRIVATE ${ARG_PRIVATE} previs_warnings)
endfunction()
