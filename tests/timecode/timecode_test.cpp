// SMPTE ST 12-1 timecode values (timecode/timecode.h): every frame of the day at every rate
// converts to its label and back, drop-frame labels agree with a plain label-by-label counter
// that skips the dropped labels, and strings parse back to the same value.
#include "timecode/timecode.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <ctime>

namespace previs {
namespace {

struct Label {
    int h = 0, m = 0, s = 0, f = 0;
};

// The label after `l`, counted one label at a time as ST 12-1 describes drop-frame: at the start
// of each minute not divisible by ten the first `drops` labels do not exist.
Label nextLabel(Label l, int nominal, int drops) {
    if (++l.f == nominal) {
        l.f = 0;
        if (++l.s == 60) {
            l.s = 0;
            if (++l.m == 60) {
                l.m = 0;
                l.h = (l.h + 1) % 24;
            }
        }
    }
    if (drops > 0 && l.s == 0 && l.f < drops && l.m % 10 != 0) l.f = drops;
    return l;
}

const TimecodeRate kAllRates[] = {TimecodeRate::fps23_976(),  TimecodeRate::fps24(),
                                  TimecodeRate::fps25(),      TimecodeRate::fps29_97(),
                                  TimecodeRate::fps29_97Df(), TimecodeRate::fps30(),
                                  TimecodeRate::fps50(),      TimecodeRate::fps59_94(),
                                  TimecodeRate::fps59_94Df(), TimecodeRate::fps60()};

// Exhaustive over 24 h: count → label matches the label counter, label → count is the inverse,
// and the string parses back (every frame of each minute's first second, where drop-frame skips
// labels, and a sample of the others).
void checkWholeDay(TimecodeRate rate, int stringEvery) {
    SCOPED_TRACE(rate.toString());
    Label expected;
    int failures = 0;
    const int64_t frames = rate.framesPerDay();
    for (int64_t count = 0; count < frames && failures < 5; ++count) {
        const Timecode tc = Timecode::fromFrameCount(count, rate);
        if (tc.hours() != expected.h || tc.minutes() != expected.m || tc.seconds() != expected.s ||
            tc.frames() != expected.f || tc.frameCount() != count) {
            ADD_FAILURE() << "frame " << count << ": " << tc.toString() << " count "
                          << tc.frameCount();
            ++failures;
        }
        if (count % stringEvery == 0 || tc.seconds() == 0) {
            const Result<Timecode> parsed = Timecode::parse(tc.toString(), rate);
            if (!parsed || !(*parsed == tc)) {
                ADD_FAILURE() << tc.toString() << " does not parse back";
                ++failures;
            }
        }
        expected = nextLabel(expected, rate.nominal(), rate.dropsPerMinute());
    }
    // After the last frame of the day the counter is back at midnight.
    EXPECT_EQ(expected.h + expected.m + expected.s + expected.f, 0);
}

TEST(SmpteTimecode, DropFrameRoundTripsEveryFrameOfTheDay) {
    checkWholeDay(TimecodeRate::fps29_97Df(), 7);
    checkWholeDay(TimecodeRate::fps59_94Df(), 7);
}

TEST(SmpteTimecode, NonDropRoundTripsEveryFrameOfTheDay) {
    for (TimecodeRate rate : kAllRates)
        if (!rate.dropFrame()) checkWholeDay(rate, 997);
}

TEST(SmpteTimecode, DropFrameKnownValues) {
    const TimecodeRate df = TimecodeRate::fps29_97Df();
    EXPECT_EQ(df.framesPerDay(), 2'589'408);
    EXPECT_EQ(TimecodeRate::fps59_94Df().framesPerDay(), 5'178'816);
    EXPECT_EQ(Timecode::fromFrameCount(1799, df).toString(), "00:00:59;29");
    EXPECT_EQ(Timecode::fromFrameCount(1800, df).toString(), "00:01:00;02");
    EXPECT_EQ(Timecode::fromFrameCount(17'982, df).toString(), "00:10:00;00");
    EXPECT_EQ(Timecode::fromFrameCount(17'982 + 1800, df).toString(), "00:11:00;02");
    EXPECT_EQ(Timecode::fromFrameCount(3600, TimecodeRate::fps59_94Df()).toString(), "00:01:00;04");
    // One hour of 29.97 DF is 107892 frames: 3.6 s of NTSC drift dropped.
    EXPECT_EQ(Timecode::parse("01:00:00;00", df)->frameCount(), 107'892);
    EXPECT_FALSE(Timecode::fromFields(0, 1, 0, 0, df)) << "a label drop-frame skips";
    EXPECT_FALSE(Timecode::fromFields(0, 1, 0, 1, df));
    EXPECT_TRUE(Timecode::fromFields(0, 10, 0, 0, df)) << "every tenth minute keeps its labels";
    EXPECT_FALSE(Timecode::fromFields(0, 1, 0, 3, TimecodeRate::fps59_94Df()));
}

TEST(SmpteTimecode, IncrementWrapsAtMidnight) {
    const TimecodeRate df = TimecodeRate::fps29_97Df();
    const Timecode last = *Timecode::fromFields(23, 59, 59, 29, df);
    EXPECT_EQ(last.next().toString(), "00:00:00;00");
    EXPECT_EQ(Timecode::fromFrameCount(-1, df), last);
    EXPECT_EQ(Timecode::parse("00:00:59;29", df)->next().toString(), "00:01:00;02");
    EXPECT_EQ(Timecode::parse("00:01:00;02", df)->plus(-1).toString(), "00:00:59;29");
    EXPECT_EQ(Timecode::parse("10:00:00:24", TimecodeRate::fps25())->next().toString(),
              "10:00:01:00");
}

TEST(SmpteTimecode, ParseRejectsWhatIsNotALabel) {
    const TimecodeRate df = TimecodeRate::fps29_97Df();
    const TimecodeRate pal = TimecodeRate::fps25();
    EXPECT_TRUE(Timecode::parse("01:02:03:04", df)) << "':' is read at a drop-frame rate too";
    EXPECT_TRUE(Timecode::parse("01:02:03.04", df));
    EXPECT_FALSE(Timecode::parse("01:02:03;04", pal)) << "';' means drop-frame";
    EXPECT_FALSE(Timecode::parse("00:01:00;00", df)) << "a dropped label";
    EXPECT_FALSE(Timecode::parse("24:00:00:00", pal));
    EXPECT_FALSE(Timecode::parse("00:00:00:25", pal));
    EXPECT_FALSE(Timecode::parse("00:60:00:00", pal));
    EXPECT_FALSE(Timecode::parse("0:00:00:00", pal));
    EXPECT_FALSE(Timecode::parse("aa:00:00:00", pal));
    const Result<Timecode> bad = Timecode::parse("00:00:00:25", pal);
    EXPECT_NE(bad.message().find("00:00:00:25"), std::string::npos) << bad.message();
}

TEST(SmpteTimecode, Rates) {
    EXPECT_EQ(*TimecodeRate::parse("29.97df"), TimecodeRate::fps29_97Df());
    EXPECT_EQ(*TimecodeRate::parse("29.97 DF"), TimecodeRate::fps29_97Df());
    EXPECT_EQ(*TimecodeRate::parse("29.97"), TimecodeRate::fps29_97());
    EXPECT_EQ(*TimecodeRate::parse("23.976"), TimecodeRate::fps23_976());
    EXPECT_EQ(*TimecodeRate::parse("59.94DF"), TimecodeRate::fps59_94Df());
    EXPECT_FALSE(TimecodeRate::parse("25df"));
    EXPECT_FALSE(TimecodeRate::parse("12"));
    EXPECT_EQ(TimecodeRate::fromFps(29.97), TimecodeRate::fps29_97());
    EXPECT_EQ(TimecodeRate::fromFps(30000.0 / 1001, true), TimecodeRate::fps29_97Df());
    EXPECT_EQ(TimecodeRate::fromFps(25.0, true), TimecodeRate::fps25()) << "no 25 fps drop-frame";
    EXPECT_EQ(TimecodeRate::fromFps(23.98), TimecodeRate::fps23_976());
    EXPECT_EQ(TimecodeRate::fromFps(60.0), TimecodeRate::fps60());
    EXPECT_EQ(TimecodeRate::fps29_97Df().toString(), "29.97 DF");
    EXPECT_EQ(TimecodeRate::fps23_976().toString(), "23.976");
    EXPECT_EQ(TimecodeRate::fps29_97().nominal(), 30);
    EXPECT_EQ(TimecodeRate::fps23_976().nominal(), 24);
    EXPECT_EQ(TimecodeRate::fps25().frameNs(), 40'000'000);
}

TEST(SmpteTimecode, ClockTimeOfDay) {
    setenv("TZ", "UTC", 1);
    tzset();
    // 2026-12-04 13:45:07.5 UTC: non-drop rates label the clock's second and count frames in it.
    const uint64_t second = 1796391907ull;
    const uint64_t ns = second * 1'000'000'000ull + 500'000'001ull;
    EXPECT_EQ(clockTimecode(ns, TimecodeRate::fps25()).toString(), "13:45:07:12");
    EXPECT_EQ(clockTimecode(ns, TimecodeRate::fps29_97()).toString(), "13:45:07:15");
    // Drop-frame counts real frames since midnight: at 10:00:00 the label is within a frame of
    // 10:00:00;00 (drop-frame is 2.6 frames short over a whole day).
    const uint64_t midnight = 1796342400ull;  // 2026-12-04 00:00:00 UTC
    const Timecode ten =
        clockTimecode((midnight + 36000) * 1'000'000'000ull, TimecodeRate::fps29_97Df());
    EXPECT_EQ(ten.hours(), 10);
    EXPECT_EQ(ten.minutes(), 0);
    EXPECT_EQ(ten.seconds(), 0);
    EXPECT_LE(ten.frames(), 1);
    EXPECT_TRUE(ten.dropFrame());
}

}  // namespace
}  // namespace previs
